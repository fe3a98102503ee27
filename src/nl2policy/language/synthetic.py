"""Synthetic (description, tree) pairs: random valid trees described in several styles.

Real writers compose a handful of moves: nested "check X; if so ... otherwise ...",
one rule per branch ("if A and not B, do C"), numbered steps, pseudo-code, arrows, texting.
Generating those moves over random trees teaches the translator the composition itself
rather than the 100-odd trees of the corpus, which is what unseen writers need.
Long descriptions add what carries no policy: why-clauses after actions, asides about the
questions and actions left out, a restated summary, a no-branch told before the yes-branch;
the generator adds those too so the translator learns to read past them.
Trees come from the random generator (never from a test fold) and from the training fold's
trees with fresh wordings.
"""

from __future__ import annotations

import random
from typing import Callable, Sequence

from nl2policy.domains import get_domain
from nl2policy.language.augment import TEXTING
from nl2policy.language.phrases import ASIDES, FILLER, SUMMARIES, UNUSED_ACTIONS, code_names
from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree, Vocabulary, to_tokens

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


Path = tuple[bool, ...]
"""Where a subtree sits: the answers (True = yes) that lead to it from the root."""




class _Words:
    def __init__(self, domain: str, rng: random.Random) -> None:
        phrases = get_domain(domain).phrases
        self.q, self.a, self.why, self.rng = phrases["questions"], phrases["actions"], phrases["reasons"], rng

    def pick(self, options: Sequence[str]) -> str:
        return self.rng.choice(list(options))

    def pos(self, q: str) -> str: return self.pick(self.q[q]["pos"])
    def neg(self, q: str) -> str: return self.pick(self.q[q]["neg"])
    def short(self, q: str, yes: bool = True) -> str: return self.pick(self.q[q]["short" if yes else "short_no"])
    def code(self, q: str) -> str: return self.pick(code_names(q))
    def act(self, a: str) -> str: return self.pick(self.a[a])

    def act_why(self, a: str, p: float = 0.3) -> str:
        """An action, sometimes with a why-clause."""
        if self.rng.random() >= p:
            return self.act(a)
        return f"{self.act(a)}{self.pick([', because ', ', since ', ' as ', ', '])}{self.pick(self.why[a])}"


def _prose(tree: Tree, w: _Words) -> str:
    """Nested prose: check, then say what happens on each answer (sometimes the no-branch first)."""
    if isinstance(tree, Leaf):
        return w.pick(["it should ", "", "just ", "then "]) + w.act_why(tree.action) + "."
    intro = w.pick(["Check whether ", "First see if ", "Ask whether ", "Look at whether ", "Then check if "])
    if w.rng.random() < 0.3:  # "If it isn't X, A. If it is, B."
        no_word = w.pick([f"If {w.neg(tree.question)}, ", f"When {w.neg(tree.question)}, "])
        yes_word = w.pick(["Otherwise, ", "If it is, ", "If so, ", f"If {w.pos(tree.question)}, "])
        return f"{no_word}{_prose(tree.no, w)} {yes_word}{_prose(tree.yes, w)}"
    no_word = w.pick(["If not, ", "Otherwise, ", "If it isn't, ", f"If {w.neg(tree.question)}, "])
    if w.rng.random() < 0.3:  # no "check whether" sentence: the condition goes in the if-clause
        return f"{w.pick(['If', 'When'])} {w.pos(tree.question)}, {_prose(tree.yes, w)} {no_word}{_prose(tree.no, w)}"
    yes_word = w.pick(["If so, ", "If it is, ", "If yes, ", f"If {w.pos(tree.question)}, "])
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
            lines.append(f"{head}{w.pick(['If', 'When'])} {joiner.join(conds)}, {w.act_why(action)}.")
        else:
            lines.append(f"{head}{joiner.join(conds)} {w.pick(['->', '→', ':', '=>'])} {w.act(action)}")
    return ("\n" if bullet or w.rng.random() < 0.5 else " ").join(lines)


def _code(tree: Tree, w: _Words, indent: int = 0) -> str:
    """Pseudo-code: if/else blocks, `if not` with the branches swapped, elif chains, arrows."""
    pad = "    " * indent
    if isinstance(tree, Leaf):
        return f"{pad}{w.act(tree.action)}"
    r = w.rng.random()
    if r < 0.35:
        return f"{pad}if {w.code(tree.question)}:\n{_code(tree.yes, w, indent + 1)}\n{pad}else:\n{_code(tree.no, w, indent + 1)}"
    if r < 0.5:
        neg = w.pick(["not ", "!", "NOT "])
        return f"{pad}if {neg}{w.code(tree.question)}:\n{_code(tree.no, w, indent + 1)}\n{pad}else:\n{_code(tree.yes, w, indent + 1)}"
    if r < 0.75 and isinstance(tree.no, Node) and isinstance(tree.yes, Leaf):  # if A -> x / else if B -> y / else -> z
        lines, node, word = [], tree, "if"
        while isinstance(node, Node) and isinstance(node.yes, Leaf):
            lines.append(f"{pad}{word} {w.code(node.question)} -> {w.act(node.yes.action)}")
            node, word = node.no, w.pick(["else if", "elif", "otherwise if"])
        rest = _code(node, w, indent + 1)
        lines.append(f"{pad}else ->\n{rest}" if isinstance(node, Node) else f"{pad}else -> {w.act(node.action)}")
        return "\n".join(lines)
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


def _asides(tree: Tree, domain: str, w: _Words) -> list[str]:
    """One or two sentences about questions or actions the tree leaves out."""
    used_q = {t for t in to_tokens(tree) if t in w.q}
    used_a = {t for t in to_tokens(tree) if t in w.a}
    out = []
    for _ in range(w.rng.choice([1, 1, 2])):
        free_q = [q for q in w.q if q not in used_q]
        free_a = [a for a in w.a if a not in used_a]
        if free_q and (not free_a or w.rng.random() < 0.7):
            q = w.short(w.pick(free_q))
            out.append(w.pick(ASIDES).format(q=q, Q=q[0].upper() + q[1:]))
        elif free_a:
            out.append(w.pick(UNUSED_ACTIONS).format(a=w.act(w.pick(free_a))))
    return out


def _drop_articles(text: str, rng: random.Random) -> str:
    """A learner's English: some articles left out."""
    return " ".join(t for t in text.split(" ") if t.lower() not in ("the", "a") or rng.random() < 0.5)


STYLES: dict[str, Callable[[Tree, _Words], str]] = {"prose": _prose, "steps": _steps, "code": _code, "arrows": _arrows}


def describe(tree: Tree, domain: str, rng: random.Random) -> str:
    """One synthetic description of `tree` in a random style, with optional asides, a restated
    summary, filler, texting and dropped articles."""
    w = _Words(domain, rng)
    style = rng.choice(list(STYLES))
    text = STYLES[style](tree, w)
    if style != "code":
        extra = _asides(tree, domain, w) if rng.random() < 0.35 else []
        if rng.random() < 0.2:
            extra.append(rng.choice(SUMMARIES) + _arrows(tree, w))
        if extra:
            text = f"{text} {' '.join(extra)}" if rng.random() < 0.8 else f"{' '.join(extra)} {text}"
        r = rng.random()
        if r < 0.25:
            text = _texting(text, rng)
        elif r < 0.35:
            text = _drop_articles(text, rng)
    if rng.random() < 0.4:
        text = f"{rng.choice(FILLER)} {text}" if rng.random() < 0.5 else f"{text}\n{rng.choice(FILLER)}"
    return text


def synthetic_pairs(domain: str, n_random: int, seed: int = 0, extra_trees: Sequence[Tree] = (),
                    per_tree: int = 1, exclude: Callable[[Tree], bool] = lambda tree: False) -> list[tuple[str, Tree]]:
    """`n_random` random trees plus `per_tree` fresh descriptions of each tree in `extra_trees`
    (pass training-fold trees only). A random tree for which `exclude` is true is drawn again: an
    evaluation that holds trees out passes them here, so no synthetic pair teaches a test tree."""
    vocab = get_domain(domain).vocab
    rng = random.Random(seed)
    trees = []
    while len(trees) < n_random:
        tree = random_tree(vocab, rng)
        if not exclude(tree):
            trees.append(tree)
    trees += [t for t in extra_trees for _ in range(per_tree)]
    return [(describe(t, domain, rng), t) for t in trees]
