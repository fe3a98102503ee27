"""PPO wall time per env step against the raw env step, per domain and method, in one run:
how much the learner (rollout forward passes + 10 epochs of minibatch updates) adds.

Run: .venv/bin/python benchmarks/ppo_overhead.py [--highway-steps N]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from nl2policy.domains import get_domain, make_env
from nl2policy.language.corpus import distinct_trees
from nl2policy.policy.sb3_policy import METHODS, make_ppo


def raw_step_seconds(domain: str, steps: int) -> float:
    env = make_env(domain)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
        if terminated or truncated:
            env.reset()
    return (time.perf_counter() - start) / steps


def ppo_step_seconds(domain: str, method: str, steps: int) -> float:
    # On the reference env, whose raw step raw_step_seconds times (highway trains on its twin by default).
    model = make_ppo(domain, method, seed=0, tree=distinct_trees(domain)[0], simulator="reference")
    start = time.perf_counter()
    model.learn(steps)
    return (time.perf_counter() - start) / model.num_timesteps


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--taxi-steps", type=int, default=4096)
    parser.add_argument("--highway-steps", type=int, default=512)
    args = parser.parse_args()
    torch.set_num_threads(1)
    for domain, steps in (("taxi", args.taxi_steps), ("highway", args.highway_steps)):
        steps = max(steps, get_domain(domain).knobs.ppo.n_steps)
        raw = raw_step_seconds(domain, steps)
        print(f"{domain}: raw env step {raw * 1e3:.3f} ms ({steps} random-action steps)")
        for method in METHODS:
            ppo = ppo_step_seconds(domain, method, steps)
            print(f"  PPO {method:10s}: {ppo * 1e3:8.3f} ms per env step  -> {ppo / raw:6.2f}x the raw env step")


if __name__ == "__main__":
    main()
