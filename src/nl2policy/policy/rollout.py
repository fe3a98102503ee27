"""Running a policy in a domain's env and scoring it, reproducibly.

Episode i of an evaluation with seed s resets the env with seed s + i, so two policies
evaluated with the same seed meet the same traffic and the same passengers (common random
numbers), and a number in a table can be made again exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from nl2policy.domains import get_domain, make_env
from nl2policy.trees import Tree

ActFn = Callable[[np.ndarray], int]


@dataclass
class Evaluation:
    mean_return: float
    stderr: float
    episodes: int
    returns: list[float]

    def summary(self) -> dict:
        return {"mean_return": self.mean_return, "stderr": self.stderr, "episodes": self.episodes}


def tree_policy(domain: str, tree: Tree) -> ActFn:
    d = get_domain(domain)
    return lambda x: d.tree_action(tree, x)


def random_policy(domain: str, seed: int = 0) -> ActFn:
    n = len(get_domain(domain).actions)
    rng = np.random.default_rng(seed)
    return lambda x: int(rng.integers(n))


def evaluate(domain: str, act: ActFn, episodes: int = 20, seed: int = 0, env=None,
             progress: Optional[Callable[[int], None]] = None) -> Evaluation:
    """Mean episode return of `act` over `episodes` seeded episodes, with its standard error."""
    if episodes < 1:
        raise ValueError("episodes must be at least 1")
    env = env or make_env(domain)
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(act(obs))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        if progress:
            progress(i + 1)
    arr = np.array(returns)
    stderr = float(arr.std(ddof=1) / math.sqrt(len(arr))) if len(arr) > 1 else 0.0
    return Evaluation(float(arr.mean()), stderr, episodes, returns)


BatchActFn = Callable[[np.ndarray], np.ndarray]


def reference_batch_act(domain: str) -> BatchActFn:
    """The domain's reference policy (spec ``reference``, one observation -> an action) on a batch."""
    d = get_domain(domain)
    act = d.attribute(d.reference)
    return lambda X: np.array([int(act(x)) for x in X], dtype=np.int64)


def evaluate_batched(domain: str, act: BatchActFn, episodes: int, seed: int) -> Evaluation:
    """Mean return of `act` (a batch of feature rows -> action indices) over `episodes`
    episodes of the domain's fast vector env (``train_env_id``), all side by side: each env's
    first episode counts. The same seed gives the same scenes, so trees scored with one seed
    meet the same traffic (common random numbers)."""
    d = get_domain(domain)
    if d.train_env_id is None:
        raise ValueError(f"{domain} has no fast vector env to evaluate on")
    if episodes < 1:
        raise ValueError("episodes must be at least 1")
    return evaluate_batched_many(domain, [act], episodes, seed)[0]


def evaluate_batched_many(domain: str, acts: list[BatchActFn], episodes: int, seed: int) -> list[Evaluation]:
    """``evaluate_batched`` of several policies on the same `episodes` scenes, in one batch of
    len(acts) x episodes (the fast env's reset option ``repeat``): the vector env's cost per step
    barely grows with the batch, so screening a hundred trees on a few scenes each costs about
    what one tree costs."""
    d = get_domain(domain)
    if d.train_env_id is None:
        raise ValueError(f"{domain} has no fast vector env to evaluate on")
    if episodes < 1 or not acts:
        raise ValueError("episodes must be at least 1, with at least one policy")
    import gymnasium as gym

    k, n = len(acts), len(acts) * episodes
    env = gym.make_vec(d.train_env_id, num_envs=n, vectorization_mode="vector_entry_point")
    # once: an env that can leave a finished episode unstepped may (only first episodes count)
    obs, _ = env.reset(seed=seed, options={"repeat": k, "once": True})
    totals, running = np.zeros(n), np.ones(n, dtype=bool)
    while running.any():
        actions = np.concatenate([np.asarray(act(obs[j * episodes:(j + 1) * episodes]), dtype=np.int64)
                                  for j, act in enumerate(acts)])
        obs, reward, terminated, truncated, _ = env.step(actions)
        totals += np.where(running, reward, 0.0)
        running &= ~(terminated | truncated)
    env.close()
    out = []
    for block in totals.reshape(k, episodes):
        stderr = float(block.std(ddof=1) / math.sqrt(episodes)) if episodes > 1 else 0.0
        out.append(Evaluation(float(block.mean()), stderr, episodes, block.tolist()))
    return out
