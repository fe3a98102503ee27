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


def test_of_equal_trees_the_fit_keeps_the_one_with_fewer_questions():
    """Scores that one question separates, listed after questions that could separate them too
    (each split by an earlier question, then the deciding one, scores the same): the one-question
    tree wins."""
    d = get_domain("taxi")
    answers = np.array([[a[q] for q in d.questions] for a in d.possible_answer_sets], dtype=bool)
    last = len(d.questions) - 1
    scores = np.zeros((len(answers), len(d.actions)))
    scores[answers[:, last], d.action_index("wait")] = 1.0
    scores[~answers[:, last], d.action_index("go_city")] = 1.0
    tree = fit_tree_scores(answers, scores, list(d.questions), list(d.actions))
    assert tree == from_tokens([d.questions[last], "wait", "go_city"], d.vocab)


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
def test_visited_rollouts_pair_each_state_with_its_action_and_advantage():
    """On highway's 16 side-by-side episodes: at the end of a rollout (after SB3 computed GAE, before
    its update reorders the buffer), row i of the kept states, actions and advantages is one
    (step, episode) of the buffer; older rows fall off the front."""
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    from nl2policy.policy.distill import VisitedStates
    from nl2policy.policy.sb3_policy import make_ppo

    class Snapshot(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            buffer = self.model.rollout_buffer
            self.copies = [np.array(buffer.observations), np.array(buffer.actions), np.array(buffer.advantages)]

    model = make_ppo("highway", "mlp", seed=0)
    keep = model.n_steps * model.n_envs + 100  # the last rollout and 100 rows of the one before
    visited, snapshot = VisitedStates(keep=keep), Snapshot()
    model.learn(model.n_steps * model.n_envs * 2, callback=CallbackList([visited, snapshot]))
    states, (actions, advantages) = visited.states(), visited.taken()
    assert model.n_envs > 1 and len(states) == len(actions) == len(advantages) == keep
    obs, acts, advs = snapshot.copies  # (n_steps, n_envs, ...): step t of episode e
    rng = np.random.default_rng(0)
    for t, e in zip(rng.integers(model.n_steps, size=20), rng.integers(model.n_envs, size=20)):
        row = 100 + t * model.n_envs + e
        assert np.array_equal(states[row], obs[t, e]) and actions[row] == int(acts[t, e, 0])
        assert advantages[row] == pytest.approx(float(advs[t, e]))
    assert not np.allclose(advantages, 0.0)


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
    probe records the soft policy before and after the move; after the last chunk nothing moves,
    so the soft policy scored at the end is the one PPO trained."""
    from nl2policy.policy.convert import ddt_to_tree
    from nl2policy.policy.optimize import train_checkpointed
    from nl2policy.policy.readings import tree_adopter
    from nl2policy.policy.sb3_policy import action_probs_fn, actor_ddt, make_ppo
    from nl2policy.trees import tree_to_json

    d = get_domain("taxi")
    start = from_tokens("has_passenger go_airport go_city".split(), d.vocab)
    target = from_tokens("has_passenger go_airport heavy_traffic go_village go_city".split(), d.vocab)
    seen = []  # at every probe: (the DDT's rounded tree, whether Adam holds moments for the actor)

    def score(model, rollouts=None):  # the checkpoint's "distilled" tree is always the target
        return tree_to_json(target), 1.0, "distilled" if rollouts is not None else "rounded"

    def probe(model, tree_json=None):
        ddt = actor_ddt(model)
        seen.append((ddt_to_tree("taxi", ddt), any(p in model.policy.optimizer.state for p in ddt.parameters())))
        return {"policy": 0.0, "soft": float(d.exact.expected_return_mixed(action_probs_fn(model)))}

    trained = train_checkpointed(lambda: make_ppo("taxi", "tree_ddt", 0, start), "taxi", 0, 1536, tmp_path,
                                 score_tree=score, probe=probe, checkpoints=3, adopt=tree_adopter("taxi"))
    # probes: step 0; then per chunk one before the move and, where it moved, one after it
    assert [("soft_before_adopt" in p) for p in trained.probes] == [False, True, True, False]
    assert len(seen) == 1 + 2 * 2 + 1
    for before, after in ((seen[1], seen[2]), (seen[3], seen[4])):
        assert after == (target, False) and before[1]  # moved onto the target, Adam's moments dropped
    assert "adopted" not in trained.last  # the last chunk's tree was read, not adopted
