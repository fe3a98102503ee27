"""Taxi's ceilings: the array model agrees with the exact model, the searches agree with brute
force on instances small enough to enumerate, and the full ceilings are ordered as they must be."""

import itertools

import numpy as np
import pytest
from typer.testing import CliRunner

from nl2policy.cli import app
from nl2policy.domains import get_domain
from nl2policy.domains.taxi.env import TaxiModel, expected_return, optimal_policy
from nl2policy.domains.taxi.tables import effective_action, taxi_tables
from nl2policy.language.corpus import distinct_trees
from nl2policy.policy.rollout import tree_policy
from nl2policy.domains.taxi.ceilings import TreeMaps, best_stationary_policy, best_tree, options
from nl2policy.trees import Leaf, Node, parse_tree
from nl2policy.trees.tree import depth

pytestmark = pytest.mark.slow

TAXI = get_domain("taxi")


@pytest.fixture(scope="module")
def tables():
    return taxi_tables()


def tree_map(tables, tree, states):
    act = tree_policy("taxi", tree)
    return tuple(effective_action(tables.states[s], act(tables.states[s].features())) for s in states)


def test_array_model_scores_policies_like_the_exact_model(tables):
    trees = distinct_trees("taxi")[:12]
    X = tables.features()
    policies = np.array([[tree_policy("taxi", t)(x) for x in X] for t in trees])
    exact = [expected_return(TaxiModel(), tree_policy("taxi", t)) for t in trees]
    assert np.allclose(tables.returns(policies), exact, atol=1e-9, rtol=0)
    everything = np.ones((1, tables.n_states, 4), dtype=bool)
    assert tables.best_returns(everything)[0] == pytest.approx(optimal_policy(TaxiModel())[0], abs=1e-9)
    assert len(tables.reachable()) == 20  # "at the airport with a passenger" never happens


def test_stationary_search_matches_brute_force_on_a_small_instance(tables):
    rng = np.random.default_rng(7)
    reach = tables.reachable()
    free = [reach[i] for i in rng.choice(len(reach), size=7, replace=False)]
    fixed = np.array([options(tables, s)[rng.integers(3)] for s in range(tables.n_states)])
    grid = []
    for combo in itertools.product(*(options(tables, s) for s in free)):
        policy = fixed.copy()
        policy[free] = combo
        grid.append(policy)
    brute = tables.returns(np.array(grid)).max()
    found = best_stationary_policy(tables, free=free, fixed=fixed)
    assert found.value == pytest.approx(brute, abs=1e-12)
    assert tables.returns(np.array([found.policy]))[0] == pytest.approx(brute, abs=1e-12)


def all_trees(max_depth):
    """Every tree of depth <= max_depth over taxi's vocabulary, valid or not."""
    if max_depth == 0:
        return [Leaf(a) for a in TAXI.actions]
    below = all_trees(max_depth - 1)
    return [Leaf(a) for a in TAXI.actions] + [Node(q, y, n) for q in TAXI.questions for y in below for n in below]


def test_realizable_maps_are_exactly_the_maps_of_all_trees(tables):
    maps = TreeMaps(tables)
    reach = tuple(tables.reachable())
    for d in (1, 2):
        brute = {tree_map(tables, t, reach) for t in all_trees(d)}
        found = maps.realizable(reach, d)
        assert set(found) == brute
        assert all(tree_map(tables, t, reach) == m and depth(t) <= d for m, t in found.items())


def test_depth_two_search_finds_the_brute_force_best(tables):
    maps = TreeMaps(tables)
    reach = tuple(tables.reachable())
    every = list(maps.realizable(reach, 2))
    brute = tables.returns(maps.policies(reach, every)).max()
    found = best_tree(tables, depth=2)
    assert found.value == pytest.approx(brute, abs=1e-12)
    assert expected_return(TaxiModel(), tree_policy("taxi", found.tree)) == pytest.approx(found.value, abs=1e-9)


def test_full_ceilings_are_ordered(tables):
    """Best depth-3 tree >= every corpus tree; best stationary policy >= best tree; <= optimum."""
    tree = best_tree(tables, depth=3)
    stationary = best_stationary_policy(tables)
    corpus = [expected_return(TaxiModel(), tree_policy("taxi", t)) for t in distinct_trees("taxi")]
    assert depth(tree.tree) <= 3
    assert expected_return(TaxiModel(), tree_policy("taxi", tree.tree)) == pytest.approx(tree.value, abs=1e-9)
    assert tree.value >= max(corpus) - 1e-12
    assert stationary.value >= tree.value - 1e-12
    assert stationary.value <= optimal_policy(TaxiModel())[0] + 1e-12


def test_sampled_ceilings_refuse_a_depth_the_climb_cannot_keep(tmp_path):
    """highway has no exact search: its ceiling is the sampled climb, which keeps the grid's depth."""
    result = CliRunner().invoke(app, ["ceilings", "--domain", "highway", "--max-depth", "2", "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == ["error: a sampled ceiling climbs trees of the grid's depth (3) only"]
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_sampled_ceiling_climbs_from_every_start_and_reports_fresh_scenes(tmp_path, monkeypatch):
    """Every state-blind tree and the example's tree is a start; the ceiling is the best by the
    confirmation scenes, its fresh score is rollout's on EVAL_SEED, and no climb ends worse than
    its start on the confirmation scenes."""
    from nl2policy.domains import get_domain
    from nl2policy.policy import ceiling_climb
    from nl2policy.policy.ceiling_climb import compute_ceilings, write_ceilings
    from nl2policy.policy.convert import tree_batch_act_fn
    from nl2policy.policy.optimize import EVAL_SEED
    from nl2policy.policy.rollout import evaluate_batched

    d = get_domain("highway")
    every = ceiling_climb.starts("highway")
    assert [name for name, _ in every] == [f"always {a}" for a in d.actions] + ["the example's tree"]
    monkeypatch.setattr(ceiling_climb, "starts", lambda domain: [every[0], every[-1]])  # two climbs: the test's time
    result = compute_ceilings("highway", screen_episodes=4, select_episodes=24, eval_episodes=16)
    climbs = result["climbs"]
    assert [c["start_name"] for c in climbs] == [every[0][0], "the example's tree"]
    assert all(c["selection"] >= c["start_selection"] for c in climbs)
    assert result["best"] == max(range(len(climbs)), key=lambda k: climbs[k]["selection"])
    best = climbs[result["best"]]
    fresh = evaluate_batched("highway", tree_batch_act_fn("highway", parse_tree(best["tree"], d.vocab)), 16, EVAL_SEED)
    assert best["fresh"]["mean"] == pytest.approx(fresh.mean_return)
    md = write_ceilings(result, tmp_path, "test")
    assert "**(ceiling)**" in md.read_text() and (tmp_path / "ceilings_highway.json").exists()


def test_stochastic_policies_are_scored_exactly(tables):
    """One-hot probabilities give the stationary return; uniform ones the random policy's."""
    from nl2policy.policy.rollout import evaluate, random_policy

    rng = np.random.default_rng(0)
    policies = rng.integers(4, size=(5, tables.n_states))
    one_hot = np.eye(4)[policies]
    assert np.allclose(tables.mixed_returns(one_hot), tables.returns(policies), atol=1e-12, rtol=0)
    uniform = get_domain("taxi").exact.expected_return_mixed(lambda X: np.full((len(X), 4), 0.25))
    sampled = evaluate("taxi", random_policy("taxi", 3), episodes=400, seed=3)
    assert abs(sampled.mean_return - uniform) < 4 * sampled.stderr
