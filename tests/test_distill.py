"""Reading a readable tree off a trained policy (nl2policy.policy.distill): the exact tree fit,
the distilled reading of a policy, and the states PPO visited."""

import itertools

import numpy as np
import pytest

from nl2policy.domains import get_domain
from nl2policy.policy.distill import VisitedStates, distilled_tree, fit_tree
from nl2policy.trees.parse import validate
from nl2policy.trees.tokens import from_tokens


def taxi_states(repeat: int = 3) -> np.ndarray:
    d = get_domain("taxi")
    rows = [[a[q] for q in d.questions] for a in d.possible_answer_sets]
    return np.array(rows * repeat, dtype=bool)


def test_fit_recovers_a_depth_three_tree_exactly():
    d = get_domain("taxi")
    gold = from_tokens("at_city has_passenger go_airport heavy_traffic wait go_village long_wait go_city at_village "
                       "go_airport wait".split(), d.vocab)
    X = taxi_states()
    y = np.array([d.action_index(gold.act(dict(zip(d.questions, row)))) for row in X])
    tree = fit_tree(X, y, np.ones(len(y)), list(d.questions), list(d.actions))
    validate(tree, d.vocab)
    assert all(tree.act(dict(zip(d.questions, row))) == gold.act(dict(zip(d.questions, row))) for row in X)


def test_fit_weighs_states_and_never_asks_in_vain():
    """Two states disagree; the heavier one wins the leaf, and a question that changes nothing is
    not asked: one label everywhere gives a single leaf."""
    d = get_domain("taxi")
    X = taxi_states(1)
    y = np.full(len(X), d.action_index("wait"))
    assert fit_tree(X, y, np.ones(len(y)), list(d.questions), list(d.actions)) == from_tokens(["wait"], d.vocab)
    w = np.ones(len(y))
    y[0], w[0] = d.action_index("go_city"), 1000.0
    tree = fit_tree(X, y, w, list(d.questions), list(d.actions))
    assert tree.act(dict(zip(d.questions, X[0]))) == "go_city"


def test_fit_is_the_optimum_among_all_small_trees():
    """Against brute force over every tree of at most 2 questions on a path, on noisy labels."""
    d = get_domain("taxi")
    rng = np.random.default_rng(0)
    X = taxi_states(2)
    y = rng.integers(len(d.actions), size=len(X))
    w = rng.random(len(X))
    Q, A = list(d.questions), list(d.actions)
    cost = lambda tree: sum(wi for row, yi, wi in zip(X, y, w) if tree.act(dict(zip(Q, row))) != A[yi])
    got = cost(fit_tree(X, y, w, Q, A, depth=2))
    best = float("inf")
    for root, left, right in itertools.product(Q, Q + [None], Q + [None]):
        for leaves in itertools.product(A, repeat=4):
            toks = [root]
            for sub, (a, b) in ((left, leaves[:2]), (right, leaves[2:])):
                toks += [sub, a, b] if sub not in (None, root) else [a]
            try:
                tree = from_tokens(toks, d.vocab)
            except Exception:
                continue
            best = min(best, cost(tree))
    assert got <= best + 1e-9


def test_the_distilled_reading_of_a_trees_own_policy_is_that_policy():
    """Probabilities that put 0.9 on a tree's action: the distilled tree acts as the tree in every
    state it was shown."""
    d = get_domain("taxi")
    gold = from_tokens("has_passenger heavy_traffic go_airport go_city at_village wait go_village".split(), d.vocab)
    states = np.array([[float(a[f]) if f in a else 0.0 for f in d.features] for a in d.possible_answer_sets])
    answers = d.answer_matrix(states)

    def probs(X):
        out = np.full((len(X), len(d.actions)), 0.1 / (len(d.actions) - 1))
        out[np.arange(len(X)), d.tree_actions(gold, X)] = 0.9
        return out

    tree = distilled_tree("taxi", probs, states)
    validate(tree, d.vocab)
    assert (d.tree_actions(tree, states) == d.tree_actions(gold, states)).all() and len(answers) == len(states)


@pytest.mark.train
def test_visited_states_are_the_rollouts_feature_rows():
    from nl2policy.policy.sb3_policy import make_ppo

    model = make_ppo("taxi", "mlp", seed=0)
    visited = VisitedStates(keep=300)
    model.learn(model.n_steps * model.n_envs * 2, callback=visited)
    X = visited.states()
    assert X.shape == (300, len(get_domain("taxi").features))
    d = get_domain("taxi")
    assert all(d.is_possible(d.answers(row)) for row in X)  # each row is a taxi situation the env can be in
