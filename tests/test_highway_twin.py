"""The highway twin: it follows highway-env car for car from the same scene, draws scenes from
the same distribution, and behaves as a Gymnasium env, a Gymnasium vector env and an SB3 VecEnv."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor

from nl2policy.domains import get_domain
from nl2policy.domains.highway.env import META_ACTION, HighwayFeatures
from nl2policy.domains.highway.geometry import RoadOrder
from nl2policy.domains.highway.scenes import copy_scene_to
from nl2policy.domains.highway.twin import HighwayTwin
from nl2policy.domains.highway.vec import HighwayTwinVectorEnv, twin_episodes
from nl2policy.policy.vec_env import SB3VecEnv
from nl2policy.trees import parse_tree

# A corpus tree that changes lanes and speed, so lane changes, MOBIL and IDM all matter.
WEAVER = {"if": "car_ahead_close",
          "yes": {"if": "right_lane_free", "yes": {"do": "lane_right"},
                  "no": {"if": "left_lane_free", "yes": {"do": "lane_left"}, "no": {"do": "slower"}}},
          "no": {"if": "going_fast", "yes": {"do": "idle"}, "no": {"do": "faster"}}}


def _weaver_actions(x: np.ndarray) -> np.ndarray:
    domain = get_domain("highway")
    return domain.tree_actions(parse_tree(WEAVER, domain.vocab), x)


@pytest.mark.parametrize("policy", ["weaver", "random"])
def test_twin_follows_highway_env_car_for_car_from_the_same_scene(policy):
    """Copy a twin scene into highway-env, drive both with the same actions: every car's
    position, the reward, the crash and the features agree at every decision."""
    episodes = 3
    twin = HighwayTwin(episodes, seed=11)
    env = HighwayFeatures()
    rng = np.random.default_rng(5)
    decisions = 0
    for e in range(episodes):
        env.reset(seed=e)
        copy_scene_to(env, twin, e)
        only = np.arange(episodes) == e
        for _ in range(30):
            features = twin.features()
            ours = int(_weaver_actions(features[e:e + 1])[0]) if policy == "weaver" else int(rng.integers(5))
            actions = np.full(episodes, 1)
            actions[e] = META_ACTION[ours]
            reward, terminated, truncated = twin.step(actions, active=only)
            obs, env_reward, env_terminated, env_truncated, _ = env.step(ours)
            cars = np.array([car.position for car in env.highway.road.vehicles])
            np.testing.assert_allclose(cars, np.stack([twin.x[e], twin.y[e]], axis=1), atol=1e-6)
            np.testing.assert_allclose(twin.features()[e], obs, atol=1e-5)
            assert reward[e] == pytest.approx(env_reward, abs=1e-9)
            assert (bool(terminated[e]), bool(truncated[e])) == (env_terminated, env_truncated)
            decisions += 1
            if env_terminated or env_truncated:
                break
    assert decisions >= 15  # the check covered several decisions of every episode


def test_twin_scenes_come_from_highway_envs_distribution():
    """Initial placement: lane shares, speeds and spacing of highway-env's resets and the twin's
    agree (means within 4 standard errors of the difference)."""
    n = 150
    env = HighwayFeatures()
    ours = HighwayTwin(2000, seed=3)
    theirs = {"ego_x": [], "gap": [], "speed": [], "lane": []}
    for seed in range(n):
        env.reset(seed=seed)
        cars = env.highway.road.vehicles
        xs = np.array([c.position[0] for c in cars])
        theirs["ego_x"].append(xs[0])
        theirs["gap"].append(np.diff(xs).mean())
        theirs["speed"].append(np.mean([c.speed for c in cars[1:]]))
        theirs["lane"].append(np.mean([c.lane_index[2] for c in cars]))
    twin = {"ego_x": ours.x[:, 0], "gap": np.diff(ours.x, axis=1).mean(axis=1),
            "speed": ours.speed[:, 1:].mean(axis=1), "lane": ours.lane.mean(axis=1)}
    for key, values in theirs.items():
        a, b = np.asarray(values), twin[key]
        se = np.hypot(a.std(ddof=1) / np.sqrt(len(a)), b.std(ddof=1) / np.sqrt(len(b)))
        assert abs(a.mean() - b.mean()) <= 4 * se + 1e-9, key


@pytest.mark.slow
def test_twin_returns_agree_with_highway_env_on_a_small_sample():
    """The random policy's mean return: 15 highway-env episodes against 1,000 twin episodes,
    within 3 standard errors of the difference (a coarse guard; the fidelity table is the
    measurement)."""
    env = HighwayFeatures()
    returns = []
    for seed in range(15):
        env.reset(seed=seed)
        rng, total, done = np.random.default_rng(seed), 0.0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(int(rng.integers(5)))
            total, done = total + reward, terminated or truncated
        returns.append(total)
    rng = np.random.default_rng(0)
    twin = twin_episodes(lambda x: rng.integers(0, 5, len(x)), 1000, seed=0)["return"]
    se = np.hypot(np.std(returns, ddof=1) / np.sqrt(len(returns)), twin.std(ddof=1) / np.sqrt(len(twin)))
    assert abs(np.mean(returns) - twin.mean()) <= 3 * se


def test_neighbour_search_matches_all_pairs():
    """The sorted scan finds, for each car, the same nearest car ahead/behind meeting a
    condition as comparing all pairs does."""
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 500, size=(40, 9))
    mask = rng.random((40, 9)) < 0.5
    order = RoadOrder(x)
    ahead, behind = order.ahead(mask), order.behind(mask)
    for n in range(40):
        for i in range(9):
            front = [j for j in range(9) if j != i and mask[n, j] and x[n, j] >= x[n, i]]
            rear = [j for j in range(9) if j != i and mask[n, j] and x[n, j] < x[n, i]]
            assert ahead[n, i] == (min(front, key=lambda j: x[n, j]) if front else 9)
            assert behind[n, i] == (max(rear, key=lambda j: x[n, j]) if rear else 9)


def test_twin_passes_gymnasiums_env_checker_and_is_seeded():
    env = gym.make("nl2policy/highway-train-v0")
    check_env(env.unwrapped, skip_render_check=True)
    first = [env.reset(seed=4)[0]] + [env.step(1)[0] for _ in range(5)]
    again = [env.reset(seed=4)[0]] + [env.step(1)[0] for _ in range(5)]
    np.testing.assert_array_equal(np.array(first), np.array(again))


def test_vector_env_resets_finished_episodes_in_the_same_step():
    vec = gym.make_vec("nl2policy/highway-train-v0", num_envs=16, vectorization_mode="vector_entry_point")
    assert isinstance(vec, HighwayTwinVectorEnv)
    obs, _ = vec.reset(seed=1)
    again, _ = vec.reset(seed=1)
    np.testing.assert_array_equal(obs, again)
    assert vec.observation_space.contains(obs)
    ended = 0
    for _ in range(31):
        obs, reward, terminated, truncated, info = vec.step(np.zeros(16, dtype=np.int64))  # lane_left
        assert vec.observation_space.contains(obs) and reward.shape == (16,)
        done = terminated | truncated
        if done.any():
            np.testing.assert_array_equal(info["_final_obs"], done)
            assert all(info["final_obs"][i].shape == (6,) for i in np.flatnonzero(done))
            assert (vec.twin.time[done] == 0).all()  # already reset
            ended += int(done.sum())
    assert ended >= 16  # every episode ends within 30 decisions
    with pytest.raises(ValueError):
        vec.step(np.full(16, 7))


def test_sb3_ppo_trains_on_the_twin_vec_env():
    env = VecMonitor(SB3VecEnv(HighwayTwinVectorEnv(16)))
    env.seed(0)
    model = PPO("MlpPolicy", env, n_steps=16, batch_size=128, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=768)
    assert model.num_timesteps >= 768
    assert len(model.ep_info_buffer) > 0  # VecMonitor saw whole episodes end


def test_highway_trains_on_the_twin_unless_told_otherwise():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from nl2policy.policy.sb3_policy import make_vec_env

    fast = make_vec_env("highway", seed=0)
    assert fast.num_envs == get_domain("highway").knobs.train_envs > 1
    assert isinstance(fast.venv, SB3VecEnv) and isinstance(fast.venv.env, HighwayTwinVectorEnv)
    assert isinstance(make_vec_env("highway", seed=0, simulator="reference"), DummyVecEnv)
    assert isinstance(make_vec_env("taxi", seed=0), DummyVecEnv)  # taxi has one simulator
    with pytest.raises(ValueError, match="unknown simulator"):
        make_vec_env("highway", seed=0, simulator="warp")


@pytest.mark.train
def test_optimize_highway_on_the_twin_reports_highway_env_returns(tmp_path):
    from nl2policy.policy.optimize import optimize_tree

    tree = parse_tree(WEAVER, get_domain("highway").vocab)
    summary = optimize_tree("highway", tree, steps=64, seed=0, out=tmp_path, eval_episodes=2, polish=False)
    assert summary["trained_on"] == "nl2policy/highway-train-v0"
    assert summary["evaluated_on"] == "nl2policy/highway-v0"
    assert summary["steps"] == 16 * 256  # one rollout of 16 twin episodes
    assert "highway-train-v0" in summary["keep_best"]["scored_by"]
    # The returned tree, read back from its file and scored afresh, is no worse than the start.
    from nl2policy.policy.keep_best import tree_from_json, tree_scorer

    score, _ = tree_scorer("highway")
    returned = tree_from_json(json.loads((tmp_path / "final_tree.json").read_text()))
    assert score(returned) >= score(tree)
    state = json.loads((tmp_path / "state.json").read_text())
    assert state["simulator"] == "fast"
    # polish off: the returned tree is the kept one, so its return is the pre-polish return
    assert summary["kept_mean_return"] == summary["final_mean_return"] and "polish" not in summary


@pytest.mark.train
def test_a_run_resumes_only_on_the_simulator_it_trained_on(tmp_path):
    from nl2policy.policy.optimize import OptimizeRefused, optimize_tree

    tree = parse_tree(WEAVER, get_domain("highway").vocab)
    optimize_tree("highway", tree, steps=64, seed=0, out=tmp_path, eval_episodes=1, polish=False)
    with pytest.raises(OptimizeRefused, match="trained on the fast simulator"):
        optimize_tree("highway", tree, steps=8192, seed=0, out=tmp_path, eval_episodes=1, simulator="reference")


def test_optimize_cli_refuses_an_unknown_simulator_and_counts_twin_rollouts(tmp_path):
    from typer.testing import CliRunner

    from nl2policy.cli import app
    from nl2policy.limits import rollout_steps

    assert rollout_steps("highway") == 16 * 256 and rollout_steps("highway", "reference") == 256
    tree = json.dumps({"do": "idle"})
    result = CliRunner().invoke(app, ["optimize", "--domain", "highway", "--tree", tree, "--simulator", "warp",
                                      "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert result.output.strip().splitlines()[-1] == "error: --simulator must be one of fast, reference, not 'warp'"


def test_with_highway_env_seeding_a_twin_episode_is_highway_envs_episode_for_that_seed():
    """Seeded as highway-env seeds itself, twin episode i is highway-env's episode with seed
    s + i: the same scene bit for bit, then the same rewards under the same policy."""
    episodes, seed = 3, 70
    ours = twin_episodes(_weaver_actions, episodes, seed, seeding="highway-env")
    env = HighwayFeatures()
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(int(_weaver_actions(obs[None, :])[0]))
            total, done = total + reward, terminated or truncated
        assert ours["return"][i] == pytest.approx(total, abs=1e-9)
    single = gym.make("nl2policy/highway-train-v0")
    np.testing.assert_array_equal(single.reset(seed=seed)[0], env.reset(seed=seed)[0])


def test_many_policies_in_one_batch_meet_the_scenes_each_would_meet_alone():
    """evaluate_batched_many lays one seed's scenes out once per policy (reset option repeat):
    each block's returns are the very returns of that policy evaluated alone."""
    from nl2policy.policy.convert import tree_batch_act_fn
    from nl2policy.policy.rollout import evaluate_batched, evaluate_batched_many

    vocab = get_domain("highway").vocab
    trees = [parse_tree(t, vocab) for t in (WEAVER, {"do": "idle"}, {"do": "faster"})]
    acts = [tree_batch_act_fn("highway", t) for t in trees]
    together = evaluate_batched_many("highway", acts, 8, 123)
    alone = [evaluate_batched("highway", act, 8, 123) for act in acts]
    assert [e.returns for e in together] == [e.returns for e in alone]
    assert len({tuple(e.returns) for e in together}) == 3  # the policies do drive differently
    with pytest.raises(ValueError, match="repeat"):
        from nl2policy.domains.highway.twin import HighwayTwin

        HighwayTwin(5).reset(np.ones(5, dtype=bool), repeat=2)
