"""Taxi's ceilings, found by exact search on the exact model: the best stationary policy on the
six features, and the best dictionary tree of depth <= 3.

Both searches score policies with ``TaxiTables`` (exact expected returns, vectorized) and are
branch and bound: a set of candidates is dropped only when an *admissible* upper bound on
every candidate in it is below the best return already found, so what remains at the end is
the maximum, not a heuristic's best.

The bound. Fix the actions of some feature states and leave the others free. Any stationary
policy that agrees with the fixed part is one policy of the relaxed problem "in a free state,
take any action, and let it depend on the tick too"; the relaxed problem's optimum (backward
induction, ``TaxiTables.best_returns``) is therefore at least that policy's return. With
every reachable state fixed the bound is the policy's exact return.

What is searched.
* Actions: driving to where the taxi is counts as waiting (``TaxiModel.outcomes``), so a state
  has 3 distinct actions, and a policy is judged by its *effective* actions.
* States: of the 24 feature states, 20 are reachable under some policy from the start (an
  empty taxi at the airport; "at the airport with a passenger" never happens: arriving there
  delivers). A policy's actions elsewhere cannot change its return.
* Trees: a tree's return depends only on the map it induces from the reachable feature
  states to effective actions, so the search enumerates maps, each once per root question.
  ``realizable_maps(S, k)`` is the set of maps on states ``S`` that some tree of depth <= k
  induces: the constants for k = 0, and for k >= 1 those of depth k - 1 together with, for
  every question q that splits S, every yes-side map of depth k - 1 on S_q joined with every
  no-side map of depth k - 1 on S \\ S_q. By induction on k this is exactly the set: a tree
  of depth <= k restricted to the states under each branch is a tree of depth <= k - 1 there;
  a question that does not split S (asked before on the path, or ruled out by the world)
  sends every state one way, so dropping it changes no action. Trees the vocabulary forbids
  (a question asked twice on a path, identical branches) induce maps a shorter valid tree
  also induces, so valid and unrestricted trees give the same maps.
* The depth-3 search: for each root question, every depth-2 yes-side map is bounded with the
  no side free and every depth-2 no-side map with the yes side free; a pair can beat the
  incumbent only if both bounds do, and the surviving pairs are scored exactly. Every map of a
  depth-3 tree is such a pair for the tree's root question (or, where a shallower tree induces
  the same map, for any question: its restrictions are depth-2 maps), and the incumbent starts
  as the best depth-2 map, scored exhaustively; so nothing is missed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, Optional, Sequence

import numpy as np

from nl2policy.domains import get_domain
from nl2policy.trees import Leaf, Node, Tree

from .env import WAIT
from .tables import N_ACTIONS, TaxiTables, effective_action

DOMAIN = __package__.rpartition(".")[2]  # this folder's name is its domain's (a copy is another domain)

TOLERANCE = 1e-9  # bounds and returns agree to ~1e-15; a candidate within this of the incumbent is kept
CHUNK = 4096  # policies scored per batched call (memory: CHUNK x 24 x 4 x 24 floats)
Map = tuple[int, ...]  # an effective action per state of a fixed, sorted state subset
Progress = Optional[Callable[[str], None]]


@dataclass
class Ceiling:
    """A search's result: the best return, the policy (an action per feature state) and,
    for a tree, the tree; with how much was looked at."""

    value: float
    policy: list[int]
    tree: Optional[Tree] = None
    counts: dict = field(default_factory=dict)
    seconds: float = 0.0


def _scores(tables: TaxiTables, masks: np.ndarray) -> np.ndarray:
    return np.concatenate([tables.best_returns(masks[i:i + CHUNK]) for i in range(0, len(masks), CHUNK)] or [np.zeros(0)])


def _returns(tables: TaxiTables, policies: np.ndarray) -> np.ndarray:
    return np.concatenate([tables.returns(policies[i:i + CHUNK]) for i in range(0, len(policies), CHUNK)] or [np.zeros(0)])


def _masks(partial: np.ndarray) -> np.ndarray:
    """Allowed-action masks (N, S, A) from partial policies (N, S): -1 = free (any action)."""
    masks = np.ones(partial.shape + (N_ACTIONS,), dtype=bool)
    fixed = partial >= 0
    masks[fixed] = False
    rows, cols = np.nonzero(fixed)
    masks[rows, cols, partial[fixed]] = True
    return masks


def options(tables: TaxiTables, state: int) -> list[int]:
    """The distinct effective actions in a feature state (3: wait, or drive to another place)."""
    return sorted({effective_action(tables.states[state], a) for a in range(N_ACTIONS)})


def coordinate_ascent(tables: TaxiTables, policy: np.ndarray, states: list[int]) -> tuple[np.ndarray, float]:
    """Improve one state's action at a time until no single change helps: a fast incumbent for
    the branch and bound (its value only prunes; it is not the answer)."""
    policy = policy.copy()
    value = float(tables.returns(policy[None])[0])
    improved = True
    while improved:
        improved = False
        for s in states:
            trials = np.repeat(policy[None], N_ACTIONS, axis=0)
            trials[:, s] = np.arange(N_ACTIONS)
            values = tables.returns(trials)
            if values.max() > value + TOLERANCE:
                policy, value, improved = trials[int(values.argmax())], float(values.max()), True
    return policy, value


def best_stationary_policy(tables: TaxiTables, progress: Progress = None,
                           free: Optional[list[int]] = None, fixed: Optional[np.ndarray] = None) -> Ceiling:
    """The best policy that maps feature states to actions, by branch and bound over the
    reachable states (or over `free` only, the others taking `fixed`'s actions: small
    instances for tests). Layer by layer: every surviving partial policy is extended by each
    action of the next state and kept while its bound reaches the incumbent."""
    start = time.perf_counter()
    reach = tables.reachable() if free is None else list(free)
    base = np.full(tables.n_states, WAIT) if fixed is None else np.asarray(fixed).copy()
    # incumbent: the plurality action of the tick-aware optimum in each state, then coordinate ascent
    seed = base.copy()
    if free is None:
        seed[reach] = [options(tables, s)[int(np.argmax(_optimal_counts(tables)[s]))] for s in reach]
    incumbent, value = coordinate_ascent(tables, seed, reach)
    order = sorted(reach, key=lambda s: -_occupancy(tables)[s])  # busiest states first: tightest bounds early
    frontier = np.where(np.isin(np.arange(tables.n_states), reach), -1, base)[None]
    counts = {"states_searched": len(reach), "policies_in_space": int(np.prod([len(options(tables, s)) for s in reach])),
              "bounds_computed": 0, "incumbent_from_coordinate_ascent": value}
    for depth, state in enumerate(order):
        children = np.repeat(frontier, len(options(tables, state)), axis=0)
        children[:, state] = np.tile(options(tables, state), len(frontier))
        bounds = _scores(tables, _masks(children))
        counts["bounds_computed"] += len(children)
        if depth == len(order) - 1:  # every reachable state fixed: the bounds are exact returns
            best = int(np.argmax(bounds))
            if bounds[best] > value:
                incumbent, value = np.where(children[best] < 0, WAIT, children[best]), float(bounds[best])
        frontier = children[bounds >= value - TOLERANCE]
        if progress:
            progress(f"stationary: state {depth + 1}/{len(order)}, {len(frontier)} partial policies kept")
    return Ceiling(value, [int(a) for a in incumbent], None, counts, time.perf_counter() - start)


@lru_cache(maxsize=2)
def _optimal_counts(tables: TaxiTables) -> np.ndarray:
    """How often each effective action is optimal in each feature state, over the ticks."""
    from .env import optimal_policy

    counts = np.zeros((tables.n_states, N_ACTIONS))
    index = {s: i for i, s in enumerate(tables.states)}
    for state, action in optimal_policy(tables.model)[1].items():
        i = index[state._replace(tick=0)]
        counts[i, options(tables, i).index(effective_action(tables.states[i], action))] += 1
    return counts


@lru_cache(maxsize=2)
def _occupancy(tables: TaxiTables) -> np.ndarray:
    """Expected visits of each feature state under the plurality-optimal stationary policy."""
    policy = np.array([options(tables, s)[int(np.argmax(_optimal_counts(tables)[s]))] for s in range(tables.n_states)])
    step = tables.next_prob[np.arange(tables.n_states), policy]
    dist, visits = tables.initial.copy(), np.zeros(tables.n_states)
    for _ in range(tables.model.shift_ticks):
        visits += dist
        dist = dist @ step
    return visits


class TreeMaps:
    """The maps from states to effective actions that trees of the domain's questions induce
    (module doc), each with one tree that induces it."""

    def __init__(self, tables: TaxiTables, domain: str = DOMAIN) -> None:
        self.tables = tables
        self.domain = get_domain(domain)
        self.answers = [self.domain.answers(s.features()) for s in tables.states]
        self._memo: dict[tuple[tuple[int, ...], int], dict[Map, Tree]] = {}

    def split(self, states: tuple[int, ...], question: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
        yes = tuple(s for s in states if self.answers[s][question])
        return yes, tuple(s for s in states if not self.answers[s][question])

    def realizable(self, states: tuple[int, ...], depth: int) -> dict[Map, Tree]:
        key = (states, depth)
        if key in self._memo:
            return self._memo[key]
        maps: dict[Map, Tree] = {}
        for action in self.domain.actions:
            a = self.domain.action_index(action)
            maps.setdefault(tuple(effective_action(self.tables.states[s], a) for s in states), Leaf(action))
        if depth > 0:
            maps.update({m: t for m, t in self.realizable(states, depth - 1).items() if m not in maps})
            for question in self.domain.questions:
                yes, no = self.split(states, question)
                if not yes or not no:
                    continue
                for my, ty in self.realizable(yes, depth - 1).items():
                    for mn, tn in self.realizable(no, depth - 1).items():
                        joined = self.join(states, yes, my, no, mn)
                        if joined not in maps:
                            maps[joined] = Node(question, ty, tn)
        self._memo[key] = maps
        return maps

    @staticmethod
    def join(states, yes, my, no, mn) -> Map:
        where = dict(zip(yes, my))
        where.update(zip(no, mn))
        return tuple(where[s] for s in states)

    def policies(self, states: tuple[int, ...], maps: list[Map]) -> np.ndarray:
        """Full policies (N, S) from maps on `states`; every other state waits."""
        out = np.full((len(maps), self.tables.n_states), WAIT)
        if maps:
            out[:, list(states)] = np.array(maps)
        return out


def best_tree(tables: TaxiTables, depth: int = 3, progress: Progress = None,
              roots: Optional[Sequence[str]] = None) -> Ceiling:
    """The best tree of depth <= `depth` (module doc: maps, bounds, why it is the maximum);
    with `roots`, the best whose root asks one of those questions (or is shallower)."""
    start = time.perf_counter()
    trees = TreeMaps(tables)
    reach = tuple(tables.reachable())
    # incumbent: the best map of depth - 1, scored exhaustively (itself the depth - 1 ceiling)
    shallow = trees.realizable(reach, depth - 1)
    shallow_maps = list(shallow)
    values = _returns(tables, trees.policies(reach, shallow_maps))
    best = int(np.argmax(values))
    value, best_map, best_tree_ = float(values[best]), shallow_maps[best], shallow[shallow_maps[best]]
    counts = {"depth": depth, "trees_unrestricted": _tree_count(len(trees.domain.questions), len(trees.domain.actions), depth),
              f"distinct_maps_depth_le_{depth - 1}": len(shallow_maps), "root_questions": {},
              "pairs_in_space": 0, "pairs_scored": 0, "side_bounds_computed": 0}
    for question in trees.domain.questions:
        yes, no = trees.split(reach, question)
        if not yes or not no or (roots is not None and question not in roots):
            continue
        sides = []
        for side, other in ((yes, no), (no, yes)):
            maps = trees.realizable(side, depth - 1)
            keys = list(maps)
            partial = np.full((len(keys), tables.n_states), -1)
            partial[:, list(side)] = np.array(keys)
            bounds = _scores(tables, _masks(partial))
            counts["side_bounds_computed"] += len(keys)
            sides.append((keys, maps, bounds))
        (ykeys, ymaps, ybounds), (nkeys, nmaps, nbounds) = sides
        counts["pairs_in_space"] += len(ykeys) * len(nkeys)
        record = {"yes_maps": len(ykeys), "no_maps": len(nkeys), "pairs_scored": 0}
        yorder, norder = np.argsort(-ybounds), np.argsort(-nbounds)
        for yi in yorder:
            if ybounds[yi] < value - TOLERANCE:
                break
            survivors = norder[nbounds[norder] >= value - TOLERANCE]
            if not len(survivors):
                break
            joined = [trees.join(reach, yes, ykeys[yi], no, nkeys[ni]) for ni in survivors]
            scores = _returns(tables, trees.policies(reach, joined))
            record["pairs_scored"] += len(joined)
            top = int(np.argmax(scores))
            if scores[top] > value:
                ni = survivors[top]
                value, best_map = float(scores[top]), joined[top]
                best_tree_ = _node(question, ymaps[ykeys[yi]], nmaps[nkeys[ni]])
        counts["pairs_scored"] += record["pairs_scored"]
        counts["root_questions"][question] = record
        if progress:
            progress(f"depth-{depth} trees: root {question} done, best {value:.4f}")
    return Ceiling(value, [int(a) for a in trees.policies(reach, [best_map])[0]], best_tree_, counts,
                   time.perf_counter() - start)


def _tree_count(questions: int, actions: int, depth: int) -> int:
    """How many trees of depth <= `depth` there are, valid or not: the space the maps stand for."""
    return actions if depth == 0 else actions + questions * _tree_count(questions, actions, depth - 1) ** 2


def _node(question: str, yes: Tree, no: Tree) -> Tree:
    return yes if yes == no else Node(question, yes, no)
