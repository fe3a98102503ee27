"""Gymnasium's LunarLander-v3 side by side, as the domain's "fast" vector env.

There is no faster lunar simulator than Box2D's, so the training env is the reference env
itself, many at once: a synchronous vector env that resets a finished episode in the same
step (what ``policy/vec_env.py`` hands to Stable-Baselines3) and takes the reset option
``repeat`` that ``policy/rollout.evaluate_batched_many`` uses to show several policies the
same scenes (common random numbers): ``num_envs / repeat`` scenes, each ``repeat`` times,
block after block, as highway's twin does. The reset option ``once`` (evaluation counts each
env's first episode only) leaves a finished episode's env unstepped, reporting it ended with
zero reward: a screen of hundreds of trees is as long as its longest episode, and most lunar
episodes end (land or crash) long before a hovering one's 1,000 steps.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import gymnasium as gym
from gymnasium.envs.box2d.lunar_lander import LunarLander
from gymnasium.vector import AutoresetMode, SyncVectorEnv

__all__ = ["LunarLander", "LunarVectorEnv"]  # LunarLander: the single env's entry point


class LunarVectorEnv(SyncVectorEnv):
    """`num_envs` LunarLander-v3 episodes stepped together; episode i of a reset with seed s
    is scene s + (i mod scenes), as ``rollout.evaluate`` seeds episode i with s + i."""

    def __init__(self, num_envs: int = 1, render_mode: Optional[str] = None) -> None:
        super().__init__([lambda: gym.make("LunarLander-v3") for _ in range(num_envs)],
                         autoreset_mode=AutoresetMode.SAME_STEP)
        self._ended: Optional[np.ndarray] = None  # set by a reset with ``once``

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        options = dict(options or {})
        repeat = int(options.pop("repeat", 1))
        self._ended = np.zeros(self.num_envs, dtype=bool) if options.pop("once", False) else None
        if repeat < 1 or self.num_envs % repeat:
            raise ValueError(f"repeat must divide num_envs ({self.num_envs}), got {repeat}")
        scenes = self.num_envs // repeat
        seeds = None if seed is None else [seed + i % scenes for i in range(self.num_envs)]
        return super().reset(seed=seeds, options=options or None)

    def step(self, actions):
        if self._ended is None:
            return super().step(actions)
        actions = np.asarray(actions).reshape(self.num_envs)
        for i, env in enumerate(self.envs):
            if self._ended[i]:
                self._rewards[i] = 0.0
                continue
            (self._env_obs[i], self._rewards[i], self._terminations[i], self._truncations[i],
             _) = env.step(actions[i])
            self._ended[i] = self._terminations[i] or self._truncations[i]
        self._observations = np.stack(self._env_obs).astype(self.single_observation_space.dtype)
        return (self._observations.copy(), self._rewards.copy(), self._terminations.copy(),
                self._truncations.copy(), {})
