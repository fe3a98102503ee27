"""The highway domain: highway-env's fast three-lane highway, seen through the features that
the seven highway questions test.

The base env is ``highway-fast-v0`` (highway-env's cheaper variant: 5 Hz simulation, one
decision per second, 30 s episodes, 20 other cars) with a Kinematics observation of the ego
car and its 4 nearest neighbours, ahead or behind, in metres (not normalized, so the
thresholds in spec.toml read as distances and speeds). ``HighwayFeatures`` turns that
observation into six interpretable features and maps our five action ids onto highway-env's
discrete meta-actions. Reward is highway-env's own: speed in [20, 30] m/s and the right lanes
pay, a crash costs and ends the episode.
"""

from __future__ import annotations

from typing import Any, Optional

import gymnasium as gym
import highway_env  # noqa: F401  (registers highway-fast-v0)
import numpy as np
from gymnasium import spaces

LANES = 3
LANE_WIDTH = 4.0  # highway-env's StraightLane.DEFAULT_WIDTH
RANGE = 100.0  # metres: farther cars count as "none in sight"
SPEED_SCALE = 40.0  # m/s

# highway-env's DiscreteMetaAction indices, in our vocabulary's action order
# (lane_left, lane_right, faster, slower, idle).
META_ACTION = (0, 2, 3, 4, 1)

BASE_CONFIG: dict[str, Any] = {
    "lanes_count": LANES,
    "observation": {
        "type": "Kinematics",
        "vehicles_count": 5,
        "features": ["presence", "x", "y", "vx", "vy"],
        "absolute": False,
        "normalize": False,
        "see_behind": True,
        "order": "sorted",
    },
    "action": {"type": "DiscreteMetaAction"},
}


def kinematics_to_features(obs: np.ndarray, lanes: int = LANES) -> np.ndarray:
    """Six features from one Kinematics observation (row 0 ego, absolute; others relative).

    gap_ahead / gap_behind: nearest car in my lane ahead / behind; left_clearance /
    right_clearance: nearest car (either way) in the neighbouring lane, 0 if there is no lane;
    lane: 0 leftmost .. 1 rightmost; speed: forward speed / 40 m/s.
    """
    ego = obs[0]
    lane = int(np.clip(np.rint(ego[2] / LANE_WIDTH), 0, lanes - 1))
    others = obs[1:][obs[1:, 0] > 0.5]
    other_lanes = np.rint((ego[2] + others[:, 2]) / LANE_WIDTH).astype(int)
    dx = others[:, 1]

    def nearest(mask: np.ndarray) -> float:
        return min(float(np.min(np.abs(dx[mask]))) if mask.any() else RANGE, RANGE) / RANGE

    same = other_lanes == lane
    gap_ahead = nearest(same & (dx > 0))
    gap_behind = nearest(same & (dx <= 0))
    left = nearest(other_lanes == lane - 1) if lane > 0 else 0.0
    right = nearest(other_lanes == lane + 1) if lane < lanes - 1 else 0.0
    position = lane / (lanes - 1)
    speed = float(np.clip(ego[3] / SPEED_SCALE, 0.0, 1.0))
    return np.array([gap_ahead, gap_behind, left, right, position, speed], dtype=np.float32)


class HighwayFeatures(gym.Env):
    """highway-env with our feature observation and our action order.

    It owns the highway-env instance instead of subclassing ``gym.Wrapper`` so that the
    registered env is itself the unwrapped env: Gymnasium's env checker and SB3's checks
    then see exactly the spaces a policy sees.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 1}

    def __init__(self, render_mode: Optional[str] = None, config: Optional[dict] = None) -> None:
        self.render_mode = render_mode
        merged = {**BASE_CONFIG, **(config or {})}
        self.highway = gym.make("highway-fast-v0", config=merged, render_mode=render_mode).unwrapped
        self.lanes = int(self.highway.config["lanes_count"])
        self.observation_space = spaces.Box(0.0, 1.0, shape=(6,), dtype=np.float32)
        self.action_space = spaces.Discrete(len(META_ACTION))
        self.last_kinematics: Optional[np.ndarray] = None

    def _features(self, obs: np.ndarray) -> np.ndarray:
        self.last_kinematics = obs
        return kinematics_to_features(obs, self.lanes)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        obs, info = self.highway.reset(seed=seed, options=options)
        return self._features(obs), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.highway.step(META_ACTION[int(action)])
        return self._features(obs), float(reward), terminated, truncated, info

    def render(self):
        return self.highway.render()

    def close(self) -> None:
        self.highway.close()
