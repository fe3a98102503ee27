"""A final polish of PPO's tree: hill climbing over questions and actions, scored exactly.

PPO moves a tree only as far as gradients through the soft DDT carry it; a tree one edit away
can be better still (measured on taxi: results/policy/ceilings_taxi.md has trees PPO's starts
rarely reach). The polish looks at every tree one edit away and moves to the best while that
improves the exact expected return:

* a leaf takes another action;
* a question node asks another question (children kept);
* a leaf becomes a question with two leaves (where the path has room: depth <= 3);
* a question node becomes a leaf.

Where no single edit improves, larger moves, where the exact model offers them
(``subtree_search()``: taxi's, in its folder's subtree.py): one proper subtree (any node below the root) is replaced by the best subtree its
position allows (depth up to the 3-question limit), the rest of the tree fixed, scored exactly
over every such subtree at once (``SubtreeSearch.best_replacement``); and, where that is stuck
too, both branches of the root are re-solved together under the root's own question
(``SubtreeSearch.best_below_root``, branch and bound as ``nl2policy ceilings``). The root's
question stays the start's unless a single edit changes it: the polish climbs from PPO's tree;
it does not search every tree (``nl2policy ceilings`` does that, as the yardstick).

Candidates are normalized (a node whose two branches came out identical is replaced by the
branch) and kept only if the vocabulary's rules accept them (``trees.validate``). The polish is
reported beside PPO's tree, never instead of it (``optimize_tree`` writes both).

A domain without an exact model but with a fast vector env (highway's twin) gets
``polish_sampled``: the same single edits, scored on sampled episodes, where a climb on noise is
the danger. Every candidate meets the same scenes (common random numbers); a round screens all
neighbours on the knobs' ``polish_screen_episodes`` (seed ``POLISH_SEED``), screens the best
``RESCREEN_BEST`` again on ``RESCREEN_FACTOR`` times as many, then confirms the best few on
keep-best's ``select_episodes`` (seed ``SELECT_SEED``): the polish accepts a tree only where its
per-episode gain over the last accepted tree is ``CONFIRM_Z`` paired standard errors above zero.
Where no neighbour confirms, the climb may still take the best screened move and look on from
there, up to ``MAX_AHEAD`` unconfirmed moves past the last accepted tree; a tree found there is
accepted only by the same confirmation against the last accepted one, so the whole path is judged
at once. Single edits of a lunar tree rarely change its return by more than the noise, and good
trees are several edits away (the example tree: no single edit confirmed; see lunar's knobs).
Neither seed is ``optimize``'s reporting seed, so a reported gain is not the selection's own
noise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Iterator, Optional

from nl2policy.domains import get_domain
from nl2policy.policy.convert import has_raw_tests, tree_act_fn
from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree, TreeError
from nl2policy.trees.parse import validate

MAX_ROUNDS = 50  # each round strictly improves; taxi polishes stop within a handful
MIN_GAIN = 1e-9  # a move must beat the current return by more than float noise
POLISH_SEED = 70_000  # the sampled polish's screening scenes: apart from EVAL_SEED and SELECT_SEED
CONFIRM_Z = 2.0  # a sampled move's paired gain must be this many standard errors above zero
CONFIRM_BEST = 3  # screened candidates confirmed per round, best first
RESCREEN_BEST = 16  # neighbours screened a second time, on more scenes, before any confirmation
RESCREEN_FACTOR = 4  # the second screen's scenes, in multiples of the first's
MAX_AHEAD = 3  # unconfirmed moves the sampled climb may take past the last accepted tree


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
    seen, out = {tree}, []  # trees are frozen dataclasses: equal trees hash alike
    for candidate in _edits(tree, d.questions, d.actions):
        candidate = _normalize(candidate)
        if candidate in seen:
            continue
        seen.add(candidate)
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
    subtrees = exact.subtree_search(domain) if hasattr(exact, "subtree_search") else None
    while rounds < MAX_ROUNDS:
        candidates = neighbours(domain, tree)
        values = exact.expected_returns([tree_act_fn(domain, c) for c in candidates])
        scored += len(candidates)
        best = max(range(len(candidates)), key=values.__getitem__, default=None)
        found = candidates[best] if best is not None and values[best] > value + MIN_GAIN else None
        if found is None and subtrees is not None:  # no single edit helps: the larger moves
            found, n = subtrees.best_replacement(tree, value)
            scored += n
            if found is None:
                found, n = subtrees.best_below_root(tree, value)
                scored += n
        if found is None:
            break
        # confirm with the one-policy evaluator, so "better" means better by the number reported
        confirmed = float(exact.expected_return(tree_act_fn(domain, found)))
        if confirmed <= value + MIN_GAIN:
            break
        tree, value, rounds = found, confirmed, rounds + 1
    return Polished(tree, value, start_value, rounds, scored, time.perf_counter() - start)


def _positions(tree: Tree, path: tuple[tuple[str, bool], ...] = ()) -> Iterator[tuple[tuple[tuple[str, bool], ...], Tree]]:
    """Every node with the (question, answer) path that leads to it, the root first."""
    yield path, tree
    if isinstance(tree, Node):
        yield from _positions(tree.yes, path + ((tree.question, True),))
        yield from _positions(tree.no, path + ((tree.question, False),))


def _replace(tree: Tree, path: tuple[tuple[str, bool], ...], new: Tree) -> Tree:
    if not path:
        return new
    (_, answer), rest = path[0], path[1:]
    if answer:
        return Node(tree.question, _replace(tree.yes, rest, new), tree.no)
    return Node(tree.question, tree.yes, _replace(tree.no, rest, new))


@lru_cache(maxsize=32)
def polish_sampled(domain: str, tree: Tree, screen_episodes: Optional[int] = None,
                   confirm_episodes: Optional[int] = None) -> Polished:
    """Best-improvement hill climbing from `tree` on the domain's fast vector env, without an
    exact model (module doc). ``value`` and ``start_value`` are mean returns over the
    ``select_episodes`` confirmation episodes; the start is kept unless a tree beats it by
    ``CONFIRM_Z`` paired standard errors there. Its scenes are fixed, so the result is a function
    of the tree: cached per process (another seed of the same start often keeps the same tree),
    with the first call's seconds. ``rounds`` counts accepted trees. The episode counts default
    to the knobs'."""
    import numpy as np

    from nl2policy.policy.convert import tree_batch_act_fn
    from nl2policy.policy.keep_best import SELECT_SEED
    from nl2policy.policy.rollout import evaluate_batched, evaluate_batched_many

    d = get_domain(domain)
    screen_n = screen_episodes or d.knobs.polish_screen_episodes
    confirm_n = confirm_episodes or d.knobs.select_episodes
    if d.train_env_id is None or not screen_n or not confirm_n:
        raise ValueError(f"a sampled polish needs a fast vector env and the knobs polish_screen_episodes and "
                         f"select_episodes; {domain} has not")
    if has_raw_tests(tree):
        raise ValueError("the tree has raw threshold tests; the polish edits vocabulary trees only")
    start = time.perf_counter()

    def returns(t: Tree, n: int, seed: int) -> np.ndarray:
        return np.asarray(evaluate_batched(domain, tree_batch_act_fn(domain, t), n, seed).returns)

    def screen(at: Tree, candidates: list[Tree], n: int) -> list[float]:
        """Mean gain of each candidate over `at` on n common screening scenes."""
        runs = evaluate_batched_many(domain, [tree_batch_act_fn(domain, t) for t in [at] + candidates], n, POLISH_SEED)
        base = np.asarray(runs[0].returns)
        return [float((np.asarray(r.returns) - base).mean()) for r in runs[1:]]

    accepted, incumbent = tree, returns(tree, confirm_n, SELECT_SEED)
    start_value, scored, rounds, steps = float(incumbent.mean()), 0, 0, 0
    current, ahead, visited = tree, 0, {tree}
    while steps < MAX_ROUNDS:
        steps += 1
        candidates = [c for c in neighbours(domain, current) if c not in visited]
        if not candidates:
            break
        gains = screen(current, candidates, screen_n)
        scored += len(candidates)
        best = sorted(range(len(candidates)), key=lambda i: -gains[i])[:RESCREEN_BEST]
        best = [i for i in best if gains[i] > MIN_GAIN]
        if not best:
            break
        regains = screen(current, [candidates[i] for i in best], screen_n * RESCREEN_FACTOR)
        ranked = [(candidates[i], g) for g, i in sorted(zip(regains, best), key=lambda p: -p[0]) if g > MIN_GAIN]
        if not ranked:
            break
        found = None
        for candidate, _ in ranked[:CONFIRM_BEST]:
            confirmed = returns(candidate, confirm_n, SELECT_SEED)
            diff = confirmed - incumbent
            if diff.mean() > CONFIRM_Z * diff.std(ddof=1) / np.sqrt(len(diff)):
                found = (candidate, confirmed)
                break
        if found is not None:
            (accepted, incumbent), rounds, ahead = found, rounds + 1, 0
            current = accepted
        elif ahead < MAX_AHEAD:
            current, ahead = ranked[0][0], ahead + 1
        else:
            break
        visited.add(current)
    return Polished(accepted, float(incumbent.mean()), start_value, rounds, scored, time.perf_counter() - start)


def can_polish(domain: str) -> bool:
    """Whether `domain` has a polish: its exact model's, or the sampled one on its fast env."""
    d = get_domain(domain)
    return d.exact is not None or (d.train_env_id is not None and bool(d.knobs.polish_screen_episodes)
                                   and bool(d.knobs.select_episodes))


def polish_any(domain: str, tree: Tree) -> Polished:
    """The domain's polish: exact where it has an exact model, else sampled."""
    return polish(domain, tree) if get_domain(domain).exact is not None else polish_sampled(domain, tree)


def polish_kept(domain: str, kept: Tree, start: Optional[Tree]) -> tuple[Polished, str]:
    """``optimize``'s polish of PPO's kept tree: (the better climb, "kept" or "start"); `start`:
    the tree PPO began from (None for a DDT with no start tree, the random DDT).

    The climb keeps the root's question unless one edit changes it, so where PPO moved the tree
    to another root the climb from the user's start can end higher (measured: taxi's never-worse
    grid, 45 of 60 returned trees within 1 % of the best depth-3 tree when only PPO's kept trees
    were climbed, 51 of 60 when the kept tree was mostly the start:
    results/policy/history/never_worse_taxi_*). With an exact model a climb takes seconds, so
    both are climbed and the better end kept (a tie keeps PPO's); a sampled climb takes minutes
    (highway: 163 s of a 100k-step run's 270 s), so there only PPO's tree is."""
    best, source = polish_any(domain, kept), "kept"
    if start is not None and get_domain(domain).exact is not None and start != kept and not has_raw_tests(start):
        from_start = polish_any(domain, start)
        if from_start.value > best.value + MIN_GAIN:
            best, source = from_start, "start"
    return best, source
