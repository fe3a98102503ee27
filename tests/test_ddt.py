"""DDT module, tree <-> DDT conversion: fidelity, padding, discretization round trip."""

import json

import numpy as np
import pytest
import torch

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.policy.convert import ddt_to_tree, pad_tree, tree_act_fn, tree_to_ddt
from nl2policy.language.corpus import distinct_trees
from nl2policy.policy.ddt import DDT, complete_shape, random_ddt
from nl2policy.policy.fidelity import agreement, uniform_states
from nl2policy.trees import Leaf, Node, parse_tree, tree_to_json
from nl2policy.trees.tree import depth


def trees_of(domain: str) -> list:
    """The corpus's distinct trees, or for a domain nobody has described (lunar) 200 distinct
    trees drawn from the tree grammar (the synthetic generator's sampler)."""
    import random

    from nl2policy.language.synthetic import random_tree

    found = distinct_trees(domain)
    if found:
        return found
    rng, d = random.Random(0), get_domain(domain)
    drawn = {json.dumps(tree_to_json(random_tree(d, rng)), sort_keys=True) for _ in range(400)}
    return [parse_tree(json.loads(t), d.vocab) for t in sorted(drawn)][:200]


def loop_ddt_probs(ddt: DDT, x: torch.Tensor) -> torch.Tensor:
    """Reference: walk every leaf's path node by node (the straightforward implementation)."""
    s = torch.sigmoid(ddt.gamma * (x @ ddt.weights.T - ddt.comparators))
    leaf_probs = torch.softmax(ddt.leaf_logits, -1)
    out = torch.zeros(x.shape[0], ddt.leaf_logits.shape[1])
    for leaf in range(ddt.shape.leaves):
        p = torch.ones(x.shape[0])
        for n in range(ddt.shape.nodes):
            if ddt.yes_path[leaf, n]:
                p = p * s[:, n]
            if ddt.no_path[leaf, n]:
                p = p * (1 - s[:, n])
        out += p[:, None] * leaf_probs[leaf]
    return out


def test_matrix_forward_matches_per_node_loop_on_an_unbalanced_tree():
    d = get_domain("highway")
    tree = Node("car_ahead_close", Node("left_lane_free", Leaf("lane_left"), Leaf("slower")), Leaf("faster"))
    ddt = tree_to_ddt("highway", tree, gamma=5.0)
    with torch.no_grad():
        ddt.leaf_logits.normal_()
    x = torch.rand(64, len(d.features))
    assert ddt.shape.leaves == 3 and ddt.shape.nodes == 2
    assert torch.allclose(ddt(x).exp(), loop_ddt_probs(ddt, x), atol=1e-5)
    assert torch.allclose(ddt(x).exp().sum(-1), torch.ones(64), atol=1e-5)


def test_random_ddt_has_8_leaves_and_gradients_reach_every_parameter():
    ddt = random_ddt(6, 5, gamma=3.0, seed=1)
    assert ddt.shape.leaves == 8 and ddt.shape.nodes == 7
    loss = -ddt(torch.rand(32, 6))[:, 0].sum()
    ddt.zero_grad()
    loss.backward()
    for p in (ddt.weights, ddt.comparators, ddt.leaf_logits):
        assert p.grad is not None and p.grad.abs().sum() > 0


def test_complete_shape_paths_cover_each_leaf_once():
    yes, no = complete_shape(3).path_matrices()
    assert torch.equal((yes + no).sum(1), torch.full((8,), 3.0))


@pytest.mark.parametrize("domain", DOMAINS)
def test_fresh_ddt_acts_like_every_corpus_tree(domain):
    states = uniform_states(domain, 10_000, seed=3)
    worst = min(agreement(domain, t, states) for t in trees_of(domain))
    assert worst >= 0.999


@pytest.mark.parametrize("domain", DOMAINS)
def test_discretizing_fresh_ddt_gives_back_every_corpus_tree(domain):
    for tree in trees_of(domain):
        assert ddt_to_tree(domain, tree_to_ddt(domain, tree)) == tree
        assert ddt_to_tree(domain, tree_to_ddt(domain, tree, pad=True)) == tree


@pytest.mark.parametrize("domain", DOMAINS)
def test_padding_fills_the_grid_and_keeps_every_action(domain):
    d = get_domain(domain)
    states = torch.as_tensor(uniform_states(domain, 1000, seed=4))
    for tree in trees_of(domain)[:30]:
        padded = pad_tree(tree, d)
        assert depth(padded) == 3 and d.same_policy(tree, padded)
        small, full = tree_to_ddt(domain, tree), tree_to_ddt(domain, tree, pad=True)
        assert full.shape.leaves == 8
        assert torch.equal(small.greedy(states), full.greedy(states))
        assert torch.allclose(small(states).exp(), full(states).exp(), atol=1e-5)


def test_discretization_maps_negated_and_drifted_tests_and_prunes():
    tree = Node("at_city", Leaf("go_airport"), Node("has_passenger", Leaf("go_airport"), Leaf("go_city")))
    ddt = tree_to_ddt("taxi", tree)
    with torch.no_grad():
        ddt.weights[0] *= -1  # "not at city": read back as at_city with the branches swapped
        ddt.comparators[0] *= -1
        ddt.comparators[1] = 0.3  # threshold drifts but stays inside (0, 1): same question for 0/1 features
    assert ddt_to_tree("taxi", ddt) == Node("at_city", tree.no, tree.yes)
    with torch.no_grad():
        ddt.comparators[1] = 1.5  # never yes on the feature box: node pruned to its no branch
    assert ddt_to_tree("taxi", ddt) == Node("at_city", Leaf("go_city"), Leaf("go_airport"))


def test_discretization_keeps_unmatched_threshold_as_raw_test():
    tree = Node("going_fast", Leaf("slower"), Leaf("faster"))
    ddt = tree_to_ddt("highway", tree)
    with torch.no_grad():
        ddt.comparators[0] = 0.4  # speed > 0.4: no highway question tests that
    out = ddt_to_tree("highway", ddt)
    assert out.question.startswith("raw:speed>0.4")
    act = tree_act_fn("highway", out)
    x = np.array([1, 1, 1, 1, 0.5, 0.5], dtype=np.float32)
    assert act(x) == get_domain("highway").action_index("slower")


@pytest.mark.parametrize("domain", DOMAINS)
def test_vectorized_tree_actions_match_domain_tree_action(domain):
    d = get_domain(domain)
    states = uniform_states(domain, 200, seed=5)
    for tree in trees_of(domain)[:10]:
        assert d.tree_actions(tree, states).tolist() == [d.tree_action(tree, x) for x in states]


def test_discretization_prunes_a_question_the_path_already_answers():
    # a padded DDT after training may ask "at the village?" under "at the airport? yes"; no taxi
    # is at both, so the discretized tree drops that node and keeps its no branch
    tree = Node("at_airport", Node("at_village", Leaf("go_city"), Leaf("wait")),
                Node("has_passenger", Leaf("go_airport"), Leaf("go_city")))
    taxi = get_domain("taxi")
    out = ddt_to_tree("taxi", tree_to_ddt("taxi", tree))
    assert out == Node("at_airport", Leaf("wait"), Node("has_passenger", Leaf("go_airport"), Leaf("go_city")))
    assert taxi.same_policy(out, tree)
    assert taxi.forced_answer({"at_airport": False, "at_city": False}, "at_village") is True
    assert taxi.forced_answer({"at_airport": False}, "at_village") is None
    assert taxi.forced_answer({}, "has_passenger") is None


def test_a_ddt_pickled_before_the_annealing_buffers_loads_with_them_neutral():
    """Checkpoints pickle the DDT in SB3's policy_kwargs; one saved before the annealing buffers
    existed must still act (as it did) when a run resumes."""
    import pickle

    from nl2policy.policy.ddt import DDT, complete_shape

    ddt = DDT(complete_shape(2), 3, 4, gamma=5.0)
    x = torch.rand(8, 3)
    before = ddt(x)
    del ddt._buffers["node_sharpness"], ddt._buffers["leaf_temperature"]
    del ddt.anneal_to, ddt.anneal_from, ddt.sharpen_to, ddt.sharpen_from
    old = pickle.loads(pickle.dumps(ddt))
    assert torch.allclose(old(x), before)
    assert (old.anneal_to, old.anneal_from, old.sharpen_to, old.sharpen_from) == (1.0, 0.0, 1.0, 0.0)
