"""Lexical tree <-> DDT.

Tree -> DDT (exact warm start). Every domain question is one linear test ``w . x > c``
(``Domain.weights`` / ``Domain.thresholds``), so a question node becomes a DDT node with
exactly those ``w`` and ``c``; only the sharpness ``gamma`` is a choice. A leaf puts
``LEAF_MASS`` of its probability on the tree's action and spreads the rest evenly.

Gamma and the leaf mass are the domain's knobs (``Domain.knobs``, from ``domains/<name>/spec.toml``,
where each value's reason is written; measured agreement for several gammas:
``results/policy/fidelity.md``, made by ``python -m experiments.policy fidelity``). Why a leaf mass works:
the tree's action must dominate (the fresh DDT should *drive* like the tree: its sampled actions
are what PPO's first episodes score), yet leave PPO some entropy to explore with. With mass m
and A actions the tree's action is the mixture's argmax whenever the right leaf's path
probability exceeds 1 / (1 + m - (1-m)/(A-1)) (~0.52 at m = 0.95), i.e. each of at most 3
nodes on the path is at least 0.81 sure: |w.x - c| > 1.45 / gamma.

Optional padding to the full 4-level grid: each leaf above the bottom row becomes a complete
subtree whose leaves all hold the same action. Its nodes test questions not yet asked on the
path, so PPO can later split the leaf; with identical leaves below, the padded DDT acts
exactly like the unpadded one, whatever those nodes answer.

DDT -> tree (discretization): ``ddt_to_tree`` below.
"""

from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np
import torch

from nl2policy.domains import get_domain
from nl2policy.domains.spec import Domain, Knobs
from nl2policy.policy.ddt import DDT, Shape
from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree
from nl2policy.trees.raw import RAW_PREFIX, RawTest
from nl2policy.trees.tree import iter_nodes


def pad_tree(tree: Tree, domain: Domain, depth: int = MAX_DEPTH) -> Tree:
    """The same policy as a complete tree of `depth` question levels (see module doc)."""

    def grow(node: Tree, level: int, asked: list[str]) -> Tree:
        if level == depth:
            return node
        if isinstance(node, Node):
            path = asked + [node.question]
            return Node(node.question, grow(node.yes, level + 1, path), grow(node.no, level + 1, path))
        question = next((q for q in domain.questions if q not in asked), domain.questions[0])
        path = asked + [question]
        return Node(question, grow(node, level + 1, path), grow(node, level + 1, path))

    return grow(tree, 0, [])


def _shape(tree: Tree) -> Shape:
    """The tree's shape, nodes and leaves numbered in pre-order (``load_tree`` fills it)."""
    yes_child: list = []
    no_child: list = []
    leaves = 0

    def visit(node: Tree) -> tuple[str, int]:
        nonlocal leaves
        if isinstance(node, Leaf):
            leaves += 1
            return ("leaf", leaves - 1)
        index = len(yes_child)
        yes_child.append(None)
        no_child.append(None)
        yes_child[index] = visit(node.yes)
        no_child[index] = visit(node.no)
        return ("node", index)

    visit(tree)
    return Shape(tuple(yes_child), tuple(no_child), leaves)


def tree_to_ddt(domain_name: str, tree: Tree, pad: bool = False, gamma: Optional[float] = None,
                knobs: Optional[Knobs] = None) -> DDT:
    """A DDT that acts like `tree` (exact weights and comparators from the domain spec); the
    sharpness and leaf mass from `knobs` (default: the domain's), `gamma` overriding."""
    domain = get_domain(domain_name)
    knobs = knobs or domain.knobs
    if pad:
        tree = pad_tree(tree, domain)
    ddt = DDT(_shape(tree), len(domain.features), len(domain.actions), knobs.ddt_gamma if gamma is None else gamma)
    load_tree(ddt, domain_name, tree, knobs.leaf_mass)
    return ddt


def load_tree(ddt: DDT, domain_name: str, tree: Tree, leaf_mass: float) -> None:
    """Set `ddt`'s tests and leaves, in place, so that it acts like `tree`, which must have the
    DDT's shape as it is or once padded to the full depth (``pad_tree``); any numbering of the
    nodes, since the two are walked together.
    ``optimize`` uses it to move a training DDT onto a tree read from it."""
    domain = get_domain(domain_name)
    n_actions = len(domain.actions)
    if sum(1 for _ in iter_nodes(tree)) != ddt.shape.nodes:
        tree = pad_tree(tree, domain)
    weights = ddt.weights.detach().clone()
    comparators = ddt.comparators.detach().clone()
    logits = torch.full_like(ddt.leaf_logits, math.log((1.0 - leaf_mass) / (n_actions - 1)))

    def walk(node: Tree, child: tuple[str, int]) -> None:
        kind, i = child
        if isinstance(node, Leaf) != (kind == "leaf"):
            raise ValueError("the tree does not have the DDT's shape")
        if kind == "leaf":
            logits[i, domain.action_index(node.action)] = math.log(leaf_mass)
            return
        w, c = domain.question_test(node.question)  # dictionary questions and learned (raw) tests
        weights[i] = torch.as_tensor(np.asarray(w), dtype=weights.dtype)
        comparators[i] = float(c)
        walk(node.yes, ddt.shape.yes_child[i])
        walk(node.no, ddt.shape.no_child[i])

    walk(tree, ("node", 0) if ddt.shape.nodes else ("leaf", 0))
    with torch.no_grad():
        ddt.weights.copy_(weights)
        ddt.comparators.copy_(comparators)
        ddt.leaf_logits.copy_(logits)


def _single_feature_questions(domain: Domain) -> list[tuple[str, int, float, float]]:
    """(question, feature, sign, threshold-in-feature-units) for single-feature questions."""
    out = []
    for q, w, c in zip(domain.questions, domain.weights, domain.thresholds):
        nonzero = np.flatnonzero(w)
        if len(nonzero) == 1:
            f = int(nonzero[0])
            out.append((q, f, float(np.sign(w[f])), float(c / w[f])))
    return out


def ddt_to_tree(domain_name: str, ddt: DDT, tolerance: Optional[float] = None) -> Tree:
    """A readable tree from a DDT: each node keeps its dominant feature and threshold, named
    as the nearest domain question with that feature and direction (branches swapped for a
    negated question) or kept as a raw test ``raw:<feature><op><threshold>``; each leaf keeps
    its most likely action. Pruned: nodes whose threshold lies outside the feature box
    (they always answer the same; the box is [0, 1] or the spec's [ranges]), questions whose answer the path already fixes (asked higher
    up, or ruled out by the world: "at the village?" under "at the airport? yes"), and nodes
    whose two branches came out identical. Each prune keeps the action in every state the world
    can produce (Domain.possible_answer_sets)."""
    domain = get_domain(domain_name)
    tol = domain.knobs.match_tolerance if tolerance is None else tolerance
    candidates = _single_feature_questions(domain)
    w = ddt.weights.detach().cpu().numpy().astype(np.float64)
    c = ddt.comparators.detach().cpu().numpy().astype(np.float64)
    leaf_actions = ddt.leaf_logits.detach().cpu().numpy().argmax(axis=1)

    def build(child: tuple[str, int], answered: dict[str, bool]) -> Tree:
        kind, i = child
        if kind == "leaf":
            return Leaf(domain.actions[int(leaf_actions[i])])
        yes_branch, no_branch = ddt.shape.yes_child[i], ddt.shape.no_child[i]
        f = int(np.argmax(np.abs(w[i])))
        weight = w[i, f]
        if abs(weight) < 1e-8:  # no test left: the node always answers by the sign of -c
            return build(yes_branch if -c[i] > 0 else no_branch, answered)
        threshold = c[i] / weight
        greater = weight > 0  # yes iff x_f > threshold (else x_f < threshold)
        low, high = domain.feature_box(f)
        if threshold >= high or threshold <= low:  # constant on the feature box
            always_yes = (threshold < low) if greater else (threshold > high)
            return build(yes_branch if always_yes else no_branch, answered)
        best = min((cand for cand in candidates if cand[1] == f), key=lambda cand: abs(cand[3] - threshold), default=None)
        if best is None or abs(best[3] - threshold) > tol:
            name = RawTest(domain.features[f], bool(greater), float(threshold)).id
            return _join(name, build(yes_branch, answered), build(no_branch, answered))
        question, _, sign, _ = best
        swapped = (sign > 0) != greater
        if swapped:
            yes_branch, no_branch = no_branch, yes_branch
        if (forced := domain.forced_answer(answered, question)) is not None:
            return build(yes_branch if forced else no_branch, answered)
        return _join(question, build(yes_branch, {**answered, question: True}),
                     build(no_branch, {**answered, question: False}))

    if ddt.shape.nodes == 0:
        return build(("leaf", 0), {})
    return build(("node", 0), {})


def _join(question: str, yes: Tree, no: Tree) -> Tree:
    return yes if yes == no else Node(question, yes, no)


def tree_act_fn(domain_name: str, tree: Tree) -> Callable[[np.ndarray], int]:
    """Act with a discretized tree, raw threshold tests included."""
    domain = get_domain(domain_name)
    return lambda x: domain.tree_action(tree, x)


def tree_batch_act_fn(domain_name: str, tree: Tree) -> Callable[[np.ndarray], np.ndarray]:
    """Act with a discretized tree on a batch of feature rows (n, features) -> (n,) indices."""
    domain = get_domain(domain_name)
    return lambda x: domain.tree_actions(tree, x)


def has_raw_tests(tree: Tree) -> bool:
    return any(n.question.startswith(RAW_PREFIX) for n in iter_nodes(tree))
