"""How well do the corpus trees drive? Mean return of every distinct corpus tree, the random
policy and (taxi) the optimum: the foundation's reference table.

Screening every tree on a few episodes and then reporting the best on the same episodes would
flatter it (the winner's curse), so the best and median trees are picked on screening seeds
and re-measured on fresh seeds.
"""

from __future__ import annotations

import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from nl2policy.domains import get_domain
from nl2policy.language.corpus import distinct_trees
from nl2policy.policy.rollout import Evaluation, evaluate, random_policy, tree_policy
from nl2policy.report import provenance
from nl2policy.trees import Tree, tree_to_json

FRESH_SEED_OFFSET = 100_000  # final measurements use seeds disjoint from screening seeds


@dataclass
class Row:
    policy: str
    mean_return: float
    stderr: float
    episodes: int
    tree: Optional[dict] = None


def _evaluate_tree(args: tuple[str, Tree, int, int]) -> Evaluation:
    """One tree's evaluation; a top-level function so a process pool can run it."""
    domain, tree, episodes, seed = args
    return evaluate(domain, tree_policy(domain, tree), episodes, seed)


def corpus_returns(domain: str, screen_episodes: int, episodes: int, seed: int, workers: int = 2,
                   progress: Optional[Callable[[int, int], None]] = None) -> list[Row]:
    trees = distinct_trees(domain)
    jobs = [(domain, t, screen_episodes, seed) for t in trees]
    screened: list[float] = []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for i, ev in enumerate(pool.map(_evaluate_tree, jobs, chunksize=4)):
            screened.append(ev.mean_return)
            if progress:
                progress(i + 1, len(trees))
    order = np.argsort(screened)
    picks = {"best corpus tree": trees[order[-1]], "median corpus tree": trees[order[len(order) // 2]]}
    fresh = seed + FRESH_SEED_OFFSET
    rows = [_row("random", evaluate(domain, random_policy(domain, fresh), episodes, fresh))]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        evals = list(pool.map(_evaluate_tree, [(domain, t, episodes, fresh) for t in picks.values()]))
    for (name, tree), ev in zip(picks.items(), evals):
        rows.append(_row(name, ev, tree_to_json(tree)))
    exact = get_domain(domain).exact
    if exact is not None:
        rows.append(Row("optimal (value iteration, exact)", exact.optimum(), 0.0, 0))
        best = picks["best corpus tree"]
        rows.append(Row("best corpus tree (exact)", exact.expected_return(tree_policy(domain, best)), 0.0, 0))
    return rows


def _row(name: str, ev, tree: Optional[dict] = None) -> Row:
    return Row(name, ev.mean_return, ev.stderr, ev.episodes, tree)


def write_returns_table(domain: str, rows: list, out: Path, command: str) -> Path:
    """results/<out>/tree_returns_<domain>.md and .json."""
    out.mkdir(parents=True, exist_ok=True)
    meta = provenance(command)
    lines = [f"# Mean episode return of reference policies: {domain}", "", f"Made by: `{command}`  ", f"On: {meta['made']}", ""]
    lines += ["| policy | mean return | stderr | episodes |", "|---|---:|---:|---:|"]
    for r in rows:
        eps = r.episodes if r.episodes else "exact"
        se = f"{r.stderr:.3f}" if r.episodes else "-"
        lines.append(f"| {r.policy} | {r.mean_return:.3f} | {se} | {eps} |")
    for r in rows:
        if r.tree:
            lines.append(f"\n{r.policy}: `{json.dumps(r.tree)}`")
    lines.append("")
    md = out / f"tree_returns_{domain}.md"
    md.write_text("\n".join(lines))
    (out / f"tree_returns_{domain}.json").write_text(json.dumps({"meta": meta, "rows": [asdict(r) for r in rows]}, indent=2))
    return md
