"""Synthetic (description, tree) pairs: random trees of every shape (trees.py) described in
general English (english.toml) with the domain's own phrases for its questions and actions.

Nobody can write descriptions of every tree in every style; a generator can. Its constructions
come from English grammar (conditionals, exceptions, defaults, lists, tables, memos, speech,
texting), never from reading the corpus, so what it teaches holds for writers and trees that
no one here has seen. Each pair is a pure function of its seed.
"""

from __future__ import annotations

import random
from typing import Callable, Collection, Sequence

from nl2policy.domains import get_domain
from nl2policy.language.synthetic.prose import sentence
from nl2policy.language.synthetic.styles import (STRUCTURED, STYLE_WEIGHTS, STYLES, arrows, asides, rules, speech,
                                                 texting, typos)
from nl2policy.language.synthetic.trees import random_tree
from nl2policy.language.synthetic.words import Words, code_names, english
from nl2policy.trees import Tree

PERSONAS = (("plain", 0.5), ("formal", 0.15), ("speech", 0.15), ("texting", 0.15), ("long", 0.05))
"""Who is writing: how the words are typed and how much is said around the policy."""


def describe(tree: Tree, domain: str, rng: random.Random, style: str | None = None, typo_rate: float = 0.2,
             styles: Collection[str] | None = None) -> str:
    """One synthetic description of `tree`: a style (STYLES, drawn by STYLE_WEIGHTS unless
    given), in a persona's register, with what people say around a policy; typos in a
    `typo_rate` share of descriptions. `styles`: the only styles it may use, anywhere (also in
    a closing summary), so an evaluation can hold whole styles out."""
    names, weights = zip(*PERSONAS)
    persona = rng.choices(names, weights)[0]
    w = Words(domain, rng, formal=persona == "formal")
    w.correct = 0.15 if persona == "speech" else 0.0
    allowed = [name for name in STYLE_WEIGHTS if styles is None or name in styles]
    if not allowed:
        raise ValueError(f"no style left to draw from: {sorted(styles or ())}")
    if style is None:
        style = rng.choices(allowed, [STYLE_WEIGHTS[name] for name in allowed])[0]
    text = STYLES[style](tree, w)
    en = english()
    before, after = [], []
    if w.chance(0.3 if persona != "long" else 1.0):
        before.append(sentence(w.en("intros")))
    chat = w.pick([3, 4, 5, 6]) if persona == "long" else (1 if w.chance(0.15) else 0)
    for _ in range(chat):
        (before if w.chance(0.5) else after).append(sentence(w.pick(en["chatter"])))
    if w.chance(0.3 if persona != "long" else 0.9):
        (after if w.chance(0.7) else before).extend(asides(tree, w))
    summaries = [f for f in (arrows, rules) if f.__name__ in allowed]
    if w.chance(0.12 if persona != "long" else 0.7) and summaries:
        after.append(w.en("summary") + w.pick(summaries)(tree, w))
    if w.chance(0.25):
        after.append(sentence(w.en("outros")))
    sep = "\n" if style in STRUCTURED or "\n" in text else " "
    text = sep.join(before + [text] + after)
    if style not in STRUCTURED:
        if persona == "speech":
            text = speech(text, rng)
        elif persona == "texting":
            text = texting(text, rng)
    if rng.random() < typo_rate:
        text = typos(text, rng)
    return text


def synthetic_pairs(domain: str, n_random: int, seed: int = 0, extra_trees: Sequence[Tree] = (),
                    per_tree: int = 1, exclude: Callable[[Tree], bool] = lambda tree: False,
                    styles: Collection[str] | None = None) -> list[tuple[str, Tree]]:
    """`n_random` random trees plus `per_tree` fresh descriptions of each tree in `extra_trees`
    (pass training-fold trees only). A random tree for which `exclude` is true is drawn again: an
    evaluation that holds trees out passes them here, so no synthetic pair teaches a test tree."""
    d = get_domain(domain)
    rng = random.Random(seed)
    trees = []
    while len(trees) < n_random:
        tree = random_tree(d, rng)
        if not exclude(tree):
            trees.append(tree)
    trees += [t for t in extra_trees for _ in range(per_tree)]
    return [(describe(t, domain, rng, styles=styles), t) for t in trees]


__all__ = ["STYLES", "code_names", "describe", "random_tree", "synthetic_pairs"]
