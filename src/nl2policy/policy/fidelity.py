"""Does the fresh DDT act like its tree? Agreement of the DDT's most likely action with the
tree's action on sampled states, for every distinct corpus tree, plus the discretization
round trip (fresh DDT -> tree gives back the same tree).

States come from two distributions, because they fail differently: the env's own states
(rolled with random actions: what the policy meets) and uniform states (taxi: every feature
vector the world can produce, equally often; highway: uniform in the [0, 1]^6 feature box,
which puts far more mass near thresholds than real traffic does).
"""

from __future__ import annotations

import numpy as np
import torch

from nl2policy.domains import get_domain, make_env
from nl2policy.policy.convert import tree_to_ddt, ddt_to_tree
from nl2policy.trees import Tree


def env_states(domain: str, n: int, seed: int = 0) -> np.ndarray:
    """`n` observations met by rolling the env with uniformly random actions."""
    env = make_env(domain)
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    states, episode = [obs], 0
    while len(states) < n:
        obs, _, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
        if terminated or truncated:
            episode += 1
            obs, _ = env.reset(seed=seed + episode)
        states.append(obs)
    return np.asarray(states, dtype=np.float32)


def uniform_states(domain: str, n: int, seed: int = 0) -> np.ndarray:
    return get_domain(domain).uniform_states(n, seed)


def agreement(domain: str, tree: Tree, states: np.ndarray, pad: bool = False, gamma: float | None = None) -> float:
    """Fraction of `states` on which the fresh DDT's argmax action is the tree's action."""
    # an unknown domain fails here, with the known ones in its message
    tree_actions = get_domain(domain).tree_actions(tree, states)
    ddt = tree_to_ddt(domain, tree, pad=pad, gamma=gamma)
    ddt_actions = ddt.greedy(torch.as_tensor(states)).numpy()
    return float(np.mean(ddt_actions == tree_actions))


def round_trips(domain: str, tree: Tree, pad: bool = False) -> bool:
    return ddt_to_tree(domain, tree_to_ddt(domain, tree, pad=pad)) == tree
