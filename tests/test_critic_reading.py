"""The critic's reading of a tree from PPO's rollouts (nl2policy.policy.advantage) and the
score-maximizing tree fit under it."""

import numpy as np
import pytest

from nl2policy.domains import get_domain
from nl2policy.policy.advantage import SHRINK, advantage_tree, cell_scores
from nl2policy.policy.distill import fit_tree_scores
from nl2policy.trees.parse import validate
from nl2policy.trees.tokens import from_tokens


def test_fit_tree_scores_maximizes_the_summed_score():
    """Scores may be negative; each cell's best action is taken where a question separates the
    cells, and one action everywhere is one leaf."""
    d = get_domain("taxi")
    answers = np.array([[a[q] for q in d.questions] for a in d.possible_answer_sets], dtype=bool)
    q = d.questions.index("heavy_traffic")
    scores = np.full((len(answers), len(d.actions)), -1.0)
    scores[answers[:, q], d.action_index("go_village")] = 2.0
    scores[~answers[:, q], d.action_index("go_city")] = 0.5
    tree = fit_tree_scores(answers, scores, list(d.questions), list(d.actions))
    assert tree == from_tokens("heavy_traffic go_village go_city".split(), d.vocab)
    flat = np.zeros_like(scores)
    flat[:, d.action_index("wait")] = 1.0
    assert fit_tree_scores(answers, flat, list(d.questions), list(d.actions)) == from_tokens(["wait"], d.vocab)


def test_the_critic_reading_follows_the_advantages_and_shrinks_rare_actions():
    """Synthetic rollouts of a policy that always waits: "go_city" pays where there is no
    passenger (advantage +1, tried often), "go_airport" was tried twice with a passenger and did
    badly. The reading sends the taxi to the city without a passenger and keeps it waiting with
    one: neither the bad action nor an untried one beats the policy's own, whatever the noise."""
    d = get_domain("taxi")
    rng = np.random.default_rng(0)
    base = np.array([[float(a[f]) if f in a else 0.0 for f in d.features] for a in d.possible_answer_sets])
    states = base[rng.integers(len(base), size=3000)]
    passenger = states[:, d.features.index("has_passenger")] > 0.5
    actions = np.full(len(states), d.action_index("wait"))
    advantages = rng.normal(0, 0.1, len(states))
    tried = ~passenger & (rng.random(len(states)) < 0.2)
    actions[tried], advantages[tried] = d.action_index("go_city"), 1.0 + rng.normal(0, 0.1, tried.sum())
    rare = np.flatnonzero(passenger)[:2]
    actions[rare], advantages[rare] = d.action_index("go_airport"), -5.0  # rare and bad

    def probs(X):
        out = np.full((len(X), len(d.actions)), 0.05)
        out[:, d.action_index("wait")] = 1 - 0.05 * (len(d.actions) - 1)
        return out

    tree = advantage_tree("taxi", probs, states, actions, advantages)
    validate(tree, d.vocab)
    assert (d.tree_actions(tree, states[~passenger]) == d.action_index("go_city")).all()
    assert (d.tree_actions(tree, states[passenger]) == d.action_index("wait")).all()
    one = d.answer_matrix(base[:1].repeat(12, axis=0))  # one cell: 10 waits at 0, 2 go_city at +3
    taken = np.array([d.action_index("wait")] * 10 + [d.action_index("go_city")] * 2)
    _, scores = cell_scores(one, taken, np.array([0.0] * 10 + [3.0] * 2), probs(base[:1].repeat(12, axis=0)))
    mean = 6.0 / 12
    assert scores[0, d.action_index("go_city")] == pytest.approx(12 * (6.0 - 2 * mean) / (2 + SHRINK) + 12 * 0.05e-6)
    assert scores[0, d.action_index("wait")] < 0 < scores[0, d.action_index("go_city")]


@pytest.mark.train
def test_visited_rollouts_record_each_states_action_and_advantage():
    from nl2policy.policy.distill import VisitedStates
    from nl2policy.policy.sb3_policy import make_ppo

    model = make_ppo("taxi", "mlp", seed=0)
    visited = VisitedStates(keep=300)
    model.learn(model.n_steps * model.n_envs, callback=visited)
    actions, advantages = visited.taken()
    buffer = model.rollout_buffer
    assert len(actions) == len(advantages) == len(visited.states()) == 300
    assert np.array_equal(actions, np.asarray(buffer.actions).reshape(-1)[-300:].astype(int))
    assert np.allclose(advantages, np.asarray(buffer.advantages).reshape(-1)[-300:])


def test_load_tree_sets_any_complete_ddt_to_act_like_a_tree():
    """A tree-initialized DDT (pre-order numbering) and the random DDT (breadth-first numbering)
    both take a depth <= 3 tree in place; a tree that cannot fit the shape is refused."""
    import torch

    from nl2policy.policy.convert import load_tree, tree_to_ddt
    from nl2policy.policy.ddt import DDT, random_ddt

    d = get_domain("taxi")
    states = np.array([[float(a[f]) if f in a else 0.0 for f in d.features] for a in d.possible_answer_sets])
    x = torch.as_tensor(states, dtype=torch.float32)
    start = from_tokens("has_passenger go_airport go_city".split(), d.vocab)
    target = from_tokens("at_village has_passenger go_airport heavy_traffic go_village go_city long_wait wait "
                         "go_city".split(), d.vocab)
    for ddt in (tree_to_ddt("taxi", start, pad=True), random_ddt(len(d.features), len(d.actions), 10.0, seed=3)):
        assert not (ddt.greedy(x).numpy() == d.tree_actions(target, states)).all()
        load_tree(ddt, "taxi", target, leaf_mass=0.7)
        assert (ddt.greedy(x).numpy() == d.tree_actions(target, states)).all()
        assert torch.allclose(ddt.leaf_logits.softmax(dim=-1).max(dim=-1).values, torch.full((8,), 0.7))
    from nl2policy.policy.ddt import Shape

    one_node = DDT(Shape((("leaf", 0),), (("leaf", 1),), 2), len(d.features), len(d.actions), 10.0)
    with pytest.raises(ValueError, match="shape"):
        load_tree(one_node, "taxi", target, leaf_mass=0.7)


@pytest.mark.train
def test_adopting_a_read_tree_moves_the_training_ddt_onto_it(tmp_path):
    """train_checkpointed with `adopt`: where a checkpoint's tree came from another reading than
    the rounding, the DDT then acts like that tree, Adam forgets the actor's moments, and the
    probe records the soft policy before and after the move."""
    from nl2policy.policy.convert import ddt_to_tree
    from nl2policy.policy.optimize import train_checkpointed, tree_adopter
    from nl2policy.policy.sb3_policy import actor_ddt, make_ppo
    from nl2policy.trees import tree_to_json

    d = get_domain("taxi")
    start = from_tokens("has_passenger go_airport go_city".split(), d.vocab)
    target = from_tokens("has_passenger go_airport heavy_traffic go_village go_city".split(), d.vocab)
    calls = []

    def score(model, rollouts=None):  # the checkpoint's "distilled" tree is always the target
        calls.append(rollouts is not None)
        return tree_to_json(target), 1.0, "distilled" if rollouts is not None else "rounded"

    def probe(model, tree_json=None):
        return {"policy": 0.0, "soft": float(d.exact.expected_return_mixed(
            lambda X: model.policy.get_distribution(torch.as_tensor(X, dtype=torch.float32)).distribution.probs.detach().numpy()))}

    import torch

    trained = train_checkpointed(lambda: make_ppo("taxi", "tree_ddt", 0, start), "taxi", 0, 1024, tmp_path, score_tree=score,
                                 probe=probe, checkpoints=2, adopt=tree_adopter("taxi"))
    ddt = actor_ddt(trained.model)
    states = np.array([[float(a[f]) if f in a else 0.0 for f in d.features] for a in d.possible_answer_sets])
    assert (ddt.greedy(torch.as_tensor(states, dtype=torch.float32)).numpy() == d.tree_actions(target, states)).all()
    assert ddt_to_tree("taxi", ddt) == target
    assert all(p not in trained.model.policy.optimizer.state for p in ddt.parameters())
    assert trained.last["adopted"] and all("soft_before_adopt" in p for p in trained.probes[1:])
    assert trained.probes[-1]["soft"] != trained.probes[-1]["soft_before_adopt"]  # measured after the move
