"""Baseline learning curves for the Optimize page, read from the policy experiment's runs
(``results/policy/<domain>/runs/<method>_s<seed>/curve.csv``): per method, the median over
seeds of the rolling mean episode return, on a common grid of env steps."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

METHODS = {"random_ddt": "random DDT", "mlp": "MLP"}
POINTS = 60


def _curve(path: Path) -> tuple[np.ndarray, np.ndarray]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    step = header.index("step")
    mean = next(i for i, h in enumerate(header) if h.startswith("rolling_mean"))
    return np.array([float(r[step]) for r in body]), np.array([float(r[mean]) for r in body])


def baseline_curves(results: Path, domain: str) -> dict:
    runs = Path(results) / "policy" / domain / "runs"
    curves: dict[str, list[list[float]]] = {}
    for prefix, name in METHODS.items():
        found = [_curve(p) for p in sorted(runs.glob(f"{prefix}_s*/curve.csv"))]
        found = [(s, m) for s, m in found if len(s) > 1]
        if not found:
            continue
        end = min(s[-1] for s, _ in found)
        grid = np.linspace(min(s[0] for s, _ in found), end, POINTS)
        median = np.median([np.interp(grid, s, m) for s, m in found], axis=0)
        curves[name] = [[float(x), float(y)] for x, y in zip(grid, median)]
    note = (f"Baselines: median over seeds of the rolling mean return, from {runs}." if curves
            else "No baseline runs found under results/policy/: run `python -m experiments.policy table2`.")
    return {"curves": curves, "note": note}
