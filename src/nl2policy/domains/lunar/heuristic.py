"""Gymnasium's hand-written lander (``gymnasium.envs.box2d.lunar_lander.heuristic``) as the
domain's reference policy: a yardstick beside the trees, not a tree itself (it mixes angle,
drift, height and speed in proportional rules that no depth-3 dictionary tree can state)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from gymnasium.envs.box2d.lunar_lander import heuristic

DISCRETE = SimpleNamespace(unwrapped=SimpleNamespace(continuous=False))
"""All the heuristic asks of its env: whether the engines are continuous (here: discrete)."""


def act(x: np.ndarray) -> int:
    """The heuristic's engine for one observation (it reads nothing else of the env)."""
    return int(heuristic(DISCRETE, np.asarray(x, dtype=np.float64)))
