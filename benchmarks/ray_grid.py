"""A small taxi Table-2 grid on Ray with 1, 2 and 4 worker CPUs, side by side in one run: wall
time and speed-up against one CPU (issue 30). Each size runs the same grid afresh into its own
temporary folder with an embedded Ray of that many CPUs; the rounds alternate the sizes so a
machine whose speed drifts treats them alike. On a 2-core machine, 4 CPUs oversubscribe the
cores: the row shows what that costs, not a gain.

Run: .venv/bin/python benchmarks/ray_grid.py [--steps 4096] [--rounds 1] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from experiments.grid import LOCAL, Job, run_jobs  # noqa: E402
from experiments.policy.table2 import plan, run_one, select_trees  # noqa: E402

SIZES = (1, 2, 4)


def _warm() -> None:
    time.sleep(0.1)


def grid_seconds(cpus: int, steps: int, tree_seeds: int, baseline_seeds: int) -> float:
    import ray

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "taxi"
        runs = plan(select_trees("taxi", 4, 2, 1, 0, root), tree_seeds, baseline_seeds)
        jobs = [Job(name, run_one, {"domain": "taxi", "method": method, "seed": seed, "steps": steps,
                                    "run_dir": root / "runs" / name, "tree_json": tree})
                for name, method, seed, tree in runs]
        ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
        try:
            # warm the workers (their imports are not the grid's work), then time the grid
            run_jobs([Job("warm", _warm)] * cpus, lambda job, r: None, ray=LOCAL)
            start = time.perf_counter()
            run_jobs(jobs, lambda job, r: None, ray=LOCAL)
            return time.perf_counter() - start
        finally:
            ray.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4096)
    parser.add_argument("--tree-seeds", type=int, default=2)
    parser.add_argument("--baseline-seeds", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    seconds = {n: [] for n in SIZES}
    for r in range(args.rounds):
        for n in (SIZES if r % 2 == 0 else SIZES[::-1]):
            seconds[n].append(grid_seconds(n, args.steps, args.tree_seeds, args.baseline_seeds))
    runs = 2 * args.tree_seeds + 2 * args.baseline_seeds
    lines = [f"# Output of: .venv/bin/python benchmarks/ray_grid.py --steps {args.steps} --tree-seeds {args.tree_seeds} "
             f"--baseline-seeds {args.baseline_seeds} --rounds {args.rounds}",
             f"# {runs} taxi PPO runs of {args.steps} steps (2 trees x {args.tree_seeds} seeds, random DDT and MLP x "
             f"{args.baseline_seeds}); {os.cpu_count()} cores, Python {platform.python_version()}, "
             f"load average at the end {os.getloadavg()[0]:.2f}",
             f"{'ray cpus':>8}  {'wall s (median)':>15}  {'speed-up':>8}"]
    base = statistics.median(seconds[1])
    for n in SIZES:
        wall = statistics.median(seconds[n])
        lines.append(f"{n:>8}  {wall:>15.1f}  {base / wall:>8.2f}")
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
