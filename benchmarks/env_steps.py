"""Env steps per second: our taxi, our highway features env, and the raw highway-env step it
wraps, measured side by side in one run so the wrapper's overhead shows as a ratio.

    .venv/bin/python benchmarks/env_steps.py [--steps 600] [--repeats 3]

Each env is stepped with the same seeded random actions. The two highway envs are timed in
alternating short rounds on identical episodes (same seed, same actions), and the ratio is the
median of the per-round ratios, so load from other processes hits both sides alike.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

from nl2policy.domains import make_env
from nl2policy.domains.highway.env import BASE_CONFIG, META_ACTION


def steps_per_second(env: gym.Env, steps: int, seed: int, map_action=lambda a: a) -> float:
    rng = np.random.default_rng(seed)
    actions = rng.integers(env.action_space.n, size=steps)
    env.reset(seed=seed)
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(map_action(int(a)))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=15, help="paired highway rounds for the ratio")
    args = parser.parse_args()
    envs = {
        "taxi (nl2policy/taxi-v0)": (make_env("taxi"), lambda a: a),
        "highway raw (highway-fast-v0, same config)": (gym.make("highway-fast-v0", config=BASE_CONFIG).unwrapped, lambda a: META_ACTION[a]),
        "highway features (nl2policy/highway-v0)": (make_env("highway").unwrapped, lambda a: a),
    }
    best = {}
    for r in range(args.repeats):  # interleave, so drift on the machine hits every env alike
        for name, (env, mapping) in envs.items():
            steps = args.steps * (20 if name.startswith("taxi") else 1)
            best[name] = max(best.get(name, 0.0), steps_per_second(env, steps, seed=r, map_action=mapping))
    for name, sps in best.items():
        print(f"{name:45s} {sps:10.1f} steps/s")
    (raw_env, raw_map), (our_env, our_map) = envs["highway raw (highway-fast-v0, same config)"], envs["highway features (nl2policy/highway-v0)"]
    ratios = []
    for r in range(args.rounds):
        raw = steps_per_second(raw_env, 60, seed=100 + r, map_action=raw_map)
        ours = steps_per_second(our_env, 60, seed=100 + r, map_action=our_map)
        ratios.append(ours / raw)
    q1, med, q3 = np.percentile(ratios, [25, 50, 75])
    print(f"feature wrapper cost ({args.rounds} paired rounds of 60 steps): our highway env runs at "
          f"{med:.3f}x the raw step rate (IQR {q1:.3f}-{q3:.3f}; {100 * (1 / med - 1):+.1f}% time per step)")


if __name__ == "__main__":
    main()
