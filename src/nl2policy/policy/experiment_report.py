"""Writing Table 2 (Markdown + JSON) and the learning-curve figure for one domain."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from nl2policy.domains import get_domain
from nl2policy.policy.experiment import LABEL
from nl2policy.policy.sb3_policy import METHODS
from nl2policy.report import provenance


def write_table(domain: str, table: dict, results: list[dict], settings: dict, out: Path, command: str) -> Path:
    meta = provenance(command)
    window = results[0]["window"]
    taxi = get_domain(domain).exact is not None  # exact columns where the domain has an exact model
    lines = [f"# Table 2 ({domain}): PPO from a tree-initialized DDT vs baselines", "",
             f"Made by: `{command}`  ", f"On: {meta['made']}  ",
             f"Settings: {json.dumps(settings)}  ",
             f"Metric: rolling mean of training episode reward over {window} episodes; initial = first full window, "
             "best = highest rolling mean; median ± standard error across runs.", "",
             "| method | runs | initial | best | final |"
             + (" initial % opt | best % opt | final policy, exact | % opt | best checkpoint tree, exact | % opt |"
                if taxi else ""),
             "|---|---:|---:|---:|---:|" + ("---:|---:|---:|---:|---:|---:|" if taxi else "")]
    for method in METHODS:
        if method not in table:
            continue
        e = table[method]
        cells = [f"{e[k]['median']:.3f} ± {e[k]['stderr']:.3f}" for k in ("initial", "best", "final")]
        row = f"| {LABEL[method]} | {e['runs']} | " + " | ".join(cells) + " |"
        if taxi:
            row += f" {e['initial']['percent_of_optimal']:.1f} | {e['best']['percent_of_optimal']:.1f} |"
            exact = e.get("exact_final")
            for exact in (e.get("exact_final"), e.get("exact_best_tree")):
                row += (f" {exact['median']:.3f} ± {exact['stderr']:.3f} | {exact['percent_of_optimal']:.1f} |" if exact
                        else " - | - |")
        lines.append(row)
    if taxi:
        lines += ["", f"Optimal expected return (value iteration on the exact model): {table['optimal_return']:.3f}", "",
                  "Exact columns: the exact expected return (`domains.taxi.expected_return`, no sampling). Final "
                  "policy = the discretized final tree (DDT methods) or the greedy final MLP. Best checkpoint tree = "
                  "the best of the discretized trees at step 0 and after every checkpoint chunk (DDT methods; what "
                  "`nl2policy optimize` writes as best_tree.json)."]
        for key, what in (("exact_gain", "final tree"), ("exact_best_gain", "best checkpoint tree")):
            gain = table.get("tree_ddt", {}).get(key)
            if gain:
                lines += ["", f"Tree-DDT runs, {what} minus initial tree (exact): median {gain['median']:+.3f}, "
                              f"mean {gain['mean']:+.3f}; better in {gain['improved']}, worse in {gain['worse']} "
                              f"of {table['tree_ddt']['runs']} runs"]
    if "tree_ddt" in table:
        gap = table["tree_ddt"]["discretized_minus_soft"]
        lines += ["", f"Discretized final tree minus soft final DDT (sampled), mean over tree-DDT runs, "
                      f"{results[0].get('eval_episodes', '?')} eval episodes each: {gap['mean']:+.3f}; "
                      f"final trees with raw (non-vocabulary) tests: {table['tree_ddt']['raw_test_trees']}"]
    exact_cols = taxi and any("exact_final" in r for r in results)
    lines += ["", "| run | initial | best | final |"
              + (" initial tree, exact | final policy, exact | best checkpoint tree, exact (step) |" if exact_cols else "")
              + " steps | seconds |", "|---|---:|---:|---:|" + ("---:|---:|---:|" if exact_cols else "") + "---:|---:|"]
    for r in results:
        name = r["method"] + (f" tree#{r.get('tree_rank', '')}" if r["method"] == "tree_ddt" else "")
        exact = ""
        if exact_cols:
            start = r.get("exact_initial_tree")
            exact = f" {start:.3f} |" if start is not None else " - |"
            exact += f" {r['exact_final']:.3f} |" if "exact_final" in r else " - |"
            exact += f" {r['exact_best_tree']:.3f} ({r['best_tree_step']}) |" if "exact_best_tree" in r else " - |"
        lines.append(f"| {name} seed {r['seed']} | {r['initial']:.3f} | {r['best']:.3f} | {r['final']:.3f} |{exact}"
                     f" {r['steps']} | {r['seconds']:.0f} |")
    md = out / f"table2_{domain}.md"
    md.write_text("\n".join(lines) + "\n")
    slim = [{k: v for k, v in r.items() if k != "curve"} for r in results]
    (out / f"table2_{domain}.json").write_text(json.dumps({"meta": meta, "settings": settings, "table": table, "runs": slim}, indent=2))
    return md


def write_figure(domain: str, results: list[dict], out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    steps_max = max(r["steps"] for r in results)
    grid = np.linspace(0, steps_max, 200)
    for method in METHODS:
        curves = [r["curve"] for r in results if r["method"] == method and r["curve"]]
        if not curves:
            continue
        interp = np.array([np.interp(grid, [s for s, _ in c], [m for _, m in c], left=np.nan) for c in curves])
        with warnings.catch_warnings():  # grid points before any run's first episode are all NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            median, low, high = (np.nanmedian(interp, axis=0), np.nanmin(interp, axis=0), np.nanmax(interp, axis=0))
        ax.plot(grid, median, label=f"{LABEL[method]} (median of {len(curves)})")
        ax.fill_between(grid, low, high, alpha=0.15)
    ax.set_xlabel("env steps")
    ax.set_ylabel(f"rolling mean episode reward ({results[0]['window']} episodes)")
    ax.set_title(f"{domain}: PPO learning curves (band: min-max across runs)")
    ax.legend()
    fig.tight_layout()
    path = out / f"curves_{domain}.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
