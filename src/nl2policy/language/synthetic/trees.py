"""Random trees for synthetic pairs: uniform over shapes within a size, sizes in the mix the
corpus's second collection round was sampled with, labels uniform over what the path allows.

A translator that has only seen the corpus's trees learns those trees; one that must read any
tree has to see every shape, deep and bushy ones included, as often as users write them.
"""

from __future__ import annotations

import random
from functools import lru_cache
from typing import Optional

from nl2policy.domains import Domain
from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree

Shape = Optional[tuple]
"""A tree's shape: None for an action, (yes shape, no shape) for a question."""

SIZE_MIX = ((1, 0.15), (2, 0.25), (3, 0.30), ((4, 5, 6, 7), 0.30))
"""Questions per tree: the size mix that round 2's trees were sampled with (corpus/round2/README:
"about 15% with one question, 25% two, 30% three, 30% four to seven"), shapes uniform within a
size (for four to seven, uniform over all their shapes together)."""


def _shapes(depth: int) -> list[Shape]:
    if depth == 0:
        return [None]
    below = _shapes(depth - 1)
    return [None] + [(a, b) for a in below for b in below]


def _size(shape: Shape) -> int:
    return 0 if shape is None else 1 + _size(shape[0]) + _size(shape[1])


@lru_cache(maxsize=None)
def shapes_by_size() -> dict[int, list[Shape]]:
    """Every shape with at most MAX_DEPTH questions on a path, by its number of questions (1: 1,
    2: 2, 3: 5, 4: 6, 5: 6, 6: 4, 7: 1)."""
    out: dict[int, list[Shape]] = {}
    for shape in _shapes(MAX_DEPTH):
        if shape is not None:
            out.setdefault(_size(shape), []).append(shape)
    return out


def random_shape(rng: random.Random) -> Shape:
    sizes, weights = zip(*SIZE_MIX)
    size = rng.choices(sizes, weights)[0]
    pool = [s for n in (size if isinstance(size, tuple) else (size,)) for s in shapes_by_size()[n]]
    return rng.choice(pool)


def _label(shape: Shape, domain: Domain, rng: random.Random, answered: dict[str, bool]) -> Optional[Tree]:
    if shape is None:
        return Leaf(rng.choice(domain.vocab.action_ids))
    free = [q for q in domain.vocab.question_ids if q not in answered and domain.forced_answer(answered, q) is None]
    if not free:
        return None
    question = rng.choice(free)
    for _ in range(20):  # the two branches must differ, or the question decides nothing
        yes = _label(shape[0], domain, rng, {**answered, question: True})
        no = _label(shape[1], domain, rng, {**answered, question: False})
        if yes is None or no is None:
            return None
        if yes != no:
            return Node(question, yes, no)
    return None


def random_tree(domain: Domain, rng: random.Random) -> Tree:
    """A random valid tree of `domain`: a shape (random_shape), then each question drawn from
    those its path neither asked nor forced (taxi: not at the airport and not at the village
    forces the city), each action uniformly, the two branches of a question never equal."""
    while True:
        tree = _label(random_shape(rng), domain, rng, {})
        if tree is not None:
            return tree
