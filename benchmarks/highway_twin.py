"""Env steps per second per core: highway-env beside the vectorized highway twin, in one run.

    .venv/bin/python benchmarks/highway_twin.py [--rounds 5] [--seconds 3]

Both simulate the same scene (highway-fast-v0 with our config, our six features) under the
same seeded random actions, finished episodes reset as they end. The twin runs N = 1, 64 and
1,024 episodes at once; an env step is one decision of one episode. Everything runs in this
one process on one core (NumPy's elementwise work is single-threaded), in alternating
rounds, so load from other processes hits every side alike; each ratio is the median of the
per-round ratios to highway-env's rate in the same round.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nl2policy.domains.highway.env import HighwayFeatures  # noqa: E402
from nl2policy.domains.highway.vec import HighwayTwinVectorEnv  # noqa: E402

SIZES = (1, 64, 1024)


def highway_env_rate(env: HighwayFeatures, seconds: float, seed: int) -> float:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = env.step(int(rng.integers(5)))
        steps += 1
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def twin_rate(env: HighwayTwinVectorEnv, seconds: float, seed: int) -> float:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(rng.integers(0, 5, env.num_envs))
        steps += env.num_envs
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds a side a round")
    args = parser.parse_args()
    reference = HighwayFeatures()
    twins = {n: HighwayTwinVectorEnv(n) for n in SIZES}
    rates: dict[str, list[float]] = {"highway-env": [], **{f"twin N={n}": [] for n in SIZES}}
    for r in range(args.rounds):
        rates["highway-env"].append(highway_env_rate(reference, args.seconds, seed=r))
        for n, env in twins.items():
            rates[f"twin N={n}"].append(twin_rate(env, args.seconds, seed=r))
    base = np.array(rates["highway-env"])
    print(f"# {args.rounds} rounds of {args.seconds:g} s a side; load average at the end: "
          f"{os.getloadavg()[0]:.2f}")
    print(f"{'simulator':20s} {'steps/s/core':>14s} {'x highway-env':>14s}")
    for name, values in rates.items():
        ratio = float(np.median(np.array(values) / base))
        print(f"{name:20s} {np.median(values):14.1f} {ratio:14.1f}")


if __name__ == "__main__":
    main()
