"""The highway twin (``highway_twin.HighwayTwin``) behind the interfaces RL code expects.

* ``HighwayTwinEnv``: one episode as a ``gymnasium.Env`` (``nl2policy/highway-train-v0``), with
  the same spaces and action order as ``nl2policy/highway-v0``, for the env checker and for
  code that steps one episode.
* ``HighwayTwinVectorEnv``: N episodes as a ``gymnasium.vector.VectorEnv``, what
  ``gymnasium.make_vec("nl2policy/highway-train-v0", num_envs=N)`` builds. It resets finished
  episodes in the same step (``AutoresetMode.SAME_STEP``: the last observation is in
  ``info["final_obs"]``), as Stable-Baselines3 expects.

``nl2policy.policy.vec_env.SB3VecEnv`` turns the vector env into a Stable-Baselines3 ``VecEnv``.

Actions are our vocabulary's order (lane_left, lane_right, faster, slower, idle), mapped to
highway-env's meta-actions by ``highway.META_ACTION`` as in ``HighwayFeatures``.
"""

from __future__ import annotations

from typing import Any, Optional

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .env import META_ACTION
from .twin import HighwayTwin, TwinConfig

_META = np.asarray(META_ACTION, dtype=np.int64)
OBSERVATION_SPACE = spaces.Box(0.0, 1.0, shape=(6,), dtype=np.float32)
ACTION_COUNT = len(META_ACTION)


def _info(twin: HighwayTwin, i: int) -> dict:
    """What highway-env's info says of episode i that our tables use."""
    return {"crashed": bool(twin.crashed[i, 0]), "speed": float(twin.speed[i, 0]),
            "forward_speed": float(twin.forward_speed()[i])}


class HighwayTwinEnv(gym.Env):
    """One twin episode as a Gymnasium env: a drop-in for ``nl2policy/highway-v0``."""

    metadata = {"render_modes": [], "render_fps": 1}

    def __init__(self, render_mode: Optional[str] = None, config: Optional[dict] = None) -> None:
        if render_mode is not None:
            raise ValueError("the highway twin does not render; use nl2policy/highway-v0 to watch a policy")
        # Seeded as highway-env seeds itself: reset(seed=s) gives highway-env's scene for s.
        self.twin = HighwayTwin(1, TwinConfig.from_highway_env(config), seeding="highway-env")
        self.observation_space = OBSERVATION_SPACE
        self.action_space = spaces.Discrete(ACTION_COUNT)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        if seed is not None:
            self.twin.seed(seed)
        self.twin.reset(np.ones(1, dtype=bool))
        return self.twin.features()[0], _info(self.twin, 0)

    def step(self, action):
        if not self.action_space.contains(action):
            raise ValueError(f"action must be an integer in [0, {ACTION_COUNT}), got {action!r}")
        reward, terminated, truncated = self.twin.step(_META[[int(action)]])
        return (self.twin.features()[0], float(reward[0]), bool(terminated[0]), bool(truncated[0]),
                _info(self.twin, 0))


class HighwayTwinVectorEnv(VectorEnv):
    """N twin episodes stepped together, reset in the step that ends them."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int = 1, render_mode: Optional[str] = None, config: Optional[dict] = None,
                 seeding: str = "batch", **_: Any) -> None:
        """`seeding`: "batch" draws every scene from one generator in batches (training);
        "highway-env" gives episode i highway-env's scenes for seed + i, at 0.6 ms a reset."""
        if render_mode is not None:
            raise ValueError("the highway twin does not render")
        self.num_envs = int(num_envs)
        self.twin = HighwayTwin(self.num_envs, TwinConfig.from_highway_env(config), seeding=seeding)
        self.single_observation_space = OBSERVATION_SPACE
        self.single_action_space = spaces.Discrete(ACTION_COUNT)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        """`options={"repeat": k}`: num_envs / k scenes, each k times, block after block
        (``HighwayTwin.reset``): k policies scored on common scenes in one batch."""
        if seed is not None:
            self.twin.seed(seed)
        self.twin.reset(np.ones(self.num_envs, dtype=bool), repeat=int((options or {}).get("repeat", 1)))
        return self.twin.features(), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        if actions.min() < 0 or actions.max() >= ACTION_COUNT:
            raise ValueError(f"actions must be integers in [0, {ACTION_COUNT})")
        reward, terminated, truncated = self.twin.step(_META[actions])
        obs = self.twin.features()
        done = terminated | truncated
        infos: dict = {"crashed": self.twin.crashed[:, 0].copy()}
        if done.any():
            final_obs = np.empty(self.num_envs, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = obs[i].copy()
            infos.update({"final_obs": final_obs, "_final_obs": done.copy()})
            self.twin.reset(done)
            obs = self.twin.features()
        return obs, reward.astype(np.float64), terminated, truncated, infos


def twin_episodes(act: Any, episodes: int, seed: int, config: Optional[dict] = None,
                  seeding: str = "batch") -> dict[str, np.ndarray]:
    """Run `episodes` twin episodes side by side, each to its end, with `act` mapping a batch of
    feature rows (n, 6) to our action indices (n,). Per episode: ``return``, ``crashed``,
    ``steps``, ``mean_speed`` (forward, m/s, over decisions) and ``right_lane`` (share of
    decisions ending in the rightmost lane). With ``seeding="highway-env"`` episode i is
    highway-env's episode with seed `seed` + i."""
    if episodes < 1:
        raise ValueError("episodes must be at least 1")
    twin = HighwayTwin(episodes, TwinConfig.from_highway_env(config), seed=seed, seeding=seeding)
    running = np.ones(episodes, dtype=bool)
    total, steps = np.zeros(episodes), np.zeros(episodes, dtype=np.int64)
    speed_sum, right = np.zeros(episodes), np.zeros(episodes)
    obs = twin.features()
    while running.any():
        actions = np.asarray(act(obs), dtype=np.int64)
        reward, terminated, truncated = twin.step(_META[actions], active=running)
        obs = twin.features()
        total += np.where(running, reward, 0.0)
        steps += running
        speed_sum += np.where(running, twin.forward_speed(), 0.0)
        right += running & (twin.lane[:, 0] == twin.config.lanes - 1)
        running &= ~(terminated | truncated)
    return {"return": total, "crashed": twin.crashed[:, 0].copy(), "steps": steps,
            "mean_speed": speed_sum / steps, "right_lane": right / steps}
