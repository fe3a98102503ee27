"""A final polish of PPO's tree: hill climbing over questions and actions, scored exactly.

PPO moves a tree only as far as gradients through the soft DDT carry it; a tree one edit away
can be better still (measured on taxi: results/policy/ceilings_taxi.md has trees PPO's starts
rarely reach). The polish looks at every tree one edit away and moves to the best while that
improves the exact expected return:

* a leaf takes another action;
* a question node asks another question (children kept);
* a leaf becomes a question with two leaves (where the path has room: depth <= 3);
* a question node becomes a leaf.

Candidates are normalized (a node whose two branches came out identical is replaced by the
branch) and kept only if the vocabulary's rules accept them (``trees.validate``). It needs
the domain's exact model: sampled returns would climb on noise. The polish is reported beside
PPO's tree, never instead of it (``optimize_tree`` writes both).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Iterator

from nl2policy.domains import get_domain
from nl2policy.policy.convert import has_raw_tests, tree_act_fn
from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree, TreeError, tree_to_json
from nl2policy.trees.parse import validate

MAX_ROUNDS = 50  # each round strictly improves; taxi polishes stop within a handful


@dataclass
class Polished:
    tree: Tree
    value: float
    start_value: float
    rounds: int
    candidates_scored: int
    seconds: float


def _normalize(tree: Tree) -> Tree:
    if isinstance(tree, Leaf):
        return tree
    yes, no = _normalize(tree.yes), _normalize(tree.no)
    return yes if yes == no else Node(tree.question, yes, no)


def _edits(tree: Tree, questions: list[str], actions: list[str], level: int = 0) -> Iterator[Tree]:
    """Every tree one edit away (module doc), before normalizing and validating."""
    if isinstance(tree, Leaf):
        yield from (Leaf(a) for a in actions if a != tree.action)
        if level < MAX_DEPTH:
            yield from (Node(q, Leaf(a), Leaf(b)) for q in questions for a in actions for b in actions if a != b)
        return
    yield from (Leaf(a) for a in actions)
    yield from (Node(q, tree.yes, tree.no) for q in questions if q != tree.question)
    yield from (Node(tree.question, yes, tree.no) for yes in _edits(tree.yes, questions, actions, level + 1))
    yield from (Node(tree.question, tree.yes, no) for no in _edits(tree.no, questions, actions, level + 1))


def neighbours(domain: str, tree: Tree) -> list[Tree]:
    """The distinct valid trees one edit from `tree`."""
    d = get_domain(domain)
    seen, out = {json.dumps(tree_to_json(tree), sort_keys=True)}, []
    for candidate in _edits(tree, d.questions, d.actions):
        candidate = _normalize(candidate)
        key = json.dumps(tree_to_json(candidate), sort_keys=True)
        if key in seen:
            continue
        seen.add(key)
        try:
            out.append(validate(candidate, d.vocab))
        except TreeError:
            continue
    return out


def polish(domain: str, tree: Tree) -> Polished:
    """Best-improvement hill climbing from `tree` on the exact model. The result is never worse
    than `tree` (the start is kept unless a neighbour is strictly better); ValueError without
    an exact model or from a tree with raw threshold tests (no vocabulary edit applies)."""
    exact = get_domain(domain).exact
    if exact is None:
        raise ValueError(f"polishing needs an exact model; {domain} has none")
    if has_raw_tests(tree):
        raise ValueError("the tree has raw threshold tests; the polish edits vocabulary trees only")
    start = time.perf_counter()
    value = start_value = float(exact.expected_return(tree_act_fn(domain, tree)))
    scored, rounds = 0, 0
    while rounds < MAX_ROUNDS:
        candidates = neighbours(domain, tree)
        values = exact.expected_returns([tree_act_fn(domain, c) for c in candidates])
        scored += len(candidates)
        best = max(range(len(candidates)), key=values.__getitem__, default=None)
        if best is None:
            break
        # confirm with the one-policy evaluator, so "better" means better by the number reported
        confirmed = float(exact.expected_return(tree_act_fn(domain, candidates[best])))
        if confirmed <= value:
            break
        tree, value, rounds = candidates[best], confirmed, rounds + 1
    return Polished(tree, value, start_value, rounds, scored, time.perf_counter() - start)
