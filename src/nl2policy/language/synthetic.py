"""Synthetic (description, tree) pairs: random valid trees described in several styles.

Real writers compose a handful of moves: nested "check X; if so ... otherwise ...",
one rule per branch ("if A and not B, do C"), numbered steps, pseudo-code, arrows, texting.
Generating those moves over random trees teaches the translator the composition itself
rather than the 100-odd trees of the corpus, which is what unseen writers need.
Trees come from the random generator (never from a test fold) and, optionally, from the
training fold's trees with fresh wordings.
"""

from __future__ import annotations

import random
from typing import Callable, Sequence

from nl2policy.domains import get_domain
from nl2policy.language.augment import TEXTING
from nl2policy.language.phrases import ACTIONS, FILLER, QUESTIONS
from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree, Vocabulary

LEAF_PROB = (0.0, 0.35, 0.55, 1.0)
"""Chance that a slot at depth d is an action: the corpus has no bare-action trees and
about as many depth-2 as depth-3 trees."""


def random_tree(vocab: Vocabulary, rng: random.Random, depth: int = 0, path: tuple[str, ...] = ()) -> Tree:
    if depth >= MAX_DEPTH or rng.random() < LEAF_PROB[depth]:
        return Leaf(rng.choice(vocab.action_ids))
    question = rng.choice([q for q in vocab.question_ids if q not in path])
    yes = random_tree(vocab, rng, depth + 1, path + (question,))
    no = random_tree(vocab, rng, depth + 1, path + (question,))
    while no == yes:
        no = random_tree(vocab, rng, depth + 1, path + (question,))
    return Node(question, yes, no)


class _Words:
    def __init__(self, domain: str, rng: random.Random) -> None:
        self.q, self.a, self.rng = QUESTIONS[domain], ACTIONS[domain], rng

    def pick(self, options: Sequence[str]) -> str:
        return self.rng.choice(list(options))

    def pos(self, q: str) -> str: return self.pick(self.q[q]["pos"])
    def neg(self, q: str) -> str: return self.pick(self.q[q]["neg"])
    def short(self, q: str, yes: bool = True) -> str: return self.pick(self.q[q]["short" if yes else "short_no"])
    def code(self, q: str) -> str: return self.pick(self.q[q]["code"])
    def act(self, a: str) -> str: return self.pick(self.a[a])


def _prose(tree: Tree, w: _Words) -> str:
    """Nested prose: check, then say what happens on each answer."""
    if isinstance(tree, Leaf):
        return w.pick(["it should ", "", "just ", "then "]) + w.act(tree.action) + "."
    intro = w.pick(["Check whether ", "First see if ", "Ask whether ", "Look at whether ", "Then check if "])
    yes_word = w.pick(["If so, ", "If it is, ", "If yes, ", f"If {w.pos(tree.question)}, "])
    no_word = w.pick(["If not, ", "Otherwise, ", "If it isn't, ", f"If {w.neg(tree.question)}, "])
    return f"{intro}{w.pos(tree.question)}. {yes_word}{_prose(tree.yes, w)} {no_word}{_prose(tree.no, w)}"


def _rules(tree: Tree, w: _Words) -> list[tuple[list[str], str]]:
    """One (conditions, action) rule per leaf: the step-by-step writers' move."""
    if isinstance(tree, Leaf):
        return [([], tree.action)]
    out = []
    for branch, yes in ((tree.yes, True), (tree.no, False)):
        for conds, action in _rules(branch, w):
            out.append(([w.pos(tree.question) if yes else w.neg(tree.question)] + conds, action))
    return out


def _steps(tree: Tree, w: _Words) -> str:
    bullet = w.pick(["{n}. ", "- ", "* ", "• ", ""])
    lines = []
    for i, (conds, action) in enumerate(_rules(tree, w)):
        head = bullet.replace("{n}", str(i + 1))
        joiner = w.pick([" and ", ", ", " and also "])
        if w.rng.random() < 0.5:
            lines.append(f"{head}If {joiner.join(conds)}, {w.act(action)}.")
        else:
            lines.append(f"{head}{joiner.join(conds)} {w.pick(['->', '→', ':', '=>'])} {w.act(action)}")
    return ("\n" if bullet or w.rng.random() < 0.5 else " ").join(lines)


def _code(tree: Tree, w: _Words, indent: int = 0) -> str:
    pad = "    " * indent
    if isinstance(tree, Leaf):
        return f"{pad}{w.act(tree.action)}"
    if w.rng.random() < 0.5:
        return f"{pad}if {w.code(tree.question)}:\n{_code(tree.yes, w, indent + 1)}\n{pad}else:\n{_code(tree.no, w, indent + 1)}"
    yes = _code(tree.yes, w, indent + 1)
    no = _code(tree.no, w, indent + 1)
    return f"{pad}{w.code(tree.question)}? ->\n{yes}\n{pad}{w.pick(['nope', 'no', 'else'])} ->\n{no}"


def _arrows(tree: Tree, w: _Words) -> str:
    if isinstance(tree, Leaf):
        return w.act(tree.action)
    return (f"{w.short(tree.question)}? {_arrows(tree.yes, w)}. "
            f"{w.pick([w.short(tree.question, False), 'if not', 'otherwise', 'no'])}: {_arrows(tree.no, w)}.")


def _texting(text: str, rng: random.Random) -> str:
    text = text.lower().replace("'", "")
    for long, short in TEXTING.items():
        if rng.random() < 0.5:
            text = text.replace(f" {long} ", f" {short} ")
    return text + (rng.choice([" lol", " thx", " ok?"]) if rng.random() < 0.2 else "")


STYLES: dict[str, Callable[[Tree, _Words], str]] = {"prose": _prose, "steps": _steps, "code": _code, "arrows": _arrows}


def describe(tree: Tree, domain: str, rng: random.Random) -> str:
    """One synthetic description of `tree` in a random style, with optional filler and texting."""
    w = _Words(domain, rng)
    style = rng.choice(list(STYLES))
    text = STYLES[style](tree, w)
    if style != "code" and rng.random() < 0.3:
        text = _texting(text, rng)
    if rng.random() < 0.4:
        text = f"{rng.choice(FILLER)} {text}" if rng.random() < 0.5 else f"{text}\n{rng.choice(FILLER)}"
    return text


def synthetic_pairs(domain: str, n_random: int, seed: int = 0, extra_trees: Sequence[Tree] = ()) -> list[tuple[str, Tree]]:
    """`n_random` random trees plus one fresh description per tree in `extra_trees` (pass
    training-fold trees only)."""
    vocab = get_domain(domain).vocab
    rng = random.Random(seed)
    trees = [random_tree(vocab, rng) for _ in range(n_random)] + list(extra_trees)
    return [(describe(t, domain, rng), t) for t in trees]
