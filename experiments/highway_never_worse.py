"""Issue 27's highway must-show: does `nl2policy optimize` improve a tree, from many starts?

Starts: the 7 most frequent distinct corpus policies and the 3 lowest-return other ones (by
keep-best's twin score), each optimized with seeds 0..seeds-1 exactly as the command runs it
(``optimize_tree``: PPO on the twin, verified keep-best, the sampled polish). Judged on
highway-env itself, `--episodes` episodes per tree from ``EVAL_SEED`` (the same scenes for
every tree, so differences are paired), against the best corpus tree:

* never worse: the returned tree's mean return >= the start's; "within noise" also counts a
  loss smaller than two paired standard errors;
* better: a paired gain more than two standard errors above zero;
* within 1 %: mean return >= 99 % of the best corpus tree's;
* gap closed: (returned - start) / (best corpus tree - start), median over runs;
* soft-vs-discrete gap: PPO's last discretized tree minus the soft DDT it came from, both
  acting on the same `--twin-episodes` twin scenes;
* seconds per run (training, keep-best, polish; not the judging).

The best corpus tree: every distinct corpus policy scored on 500 twin episodes (seed
``CEILING_SEED``), the `--ceiling-candidates` best of them on `--ceiling-episodes` highway-env
episodes, the highest of those. Every highway-env evaluation is cached in ``judged.jsonl``;
finished runs in ``runs/*/run.json``: the command resumes.

Run: ``python experiments/highway_never_worse.py --seeds 2 --steps 50000 --workers 2
--out results/policy/never_worse_highway``
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

DOMAIN = "highway"
CEILING_SEED = 900_000  # the ceiling's twin screen: apart from every seed the runs use
GAP_SEED = 90_000  # the twin scenes on which PPO's last tree and its soft DDT are compared


def key(tree_json: dict) -> str:
    return json.dumps(tree_json, sort_keys=True)


class Judge:
    """highway-env returns per tree, `episodes` episodes from EVAL_SEED, cached in a jsonl file."""

    def __init__(self, path: Path, episodes: int) -> None:
        self.path, self.episodes, self.cache = path, episodes, {}
        if path.is_file():
            for line in path.read_text().splitlines():
                row = json.loads(line)
                if row["episodes"] == episodes:
                    self.cache[row["tree"]] = row["returns"]

    def returns(self, tree_json: dict) -> np.ndarray:
        from nl2policy.domains import get_domain
        from nl2policy.policy.convert import tree_act_fn
        from nl2policy.policy.keep_best import tree_from_json
        from nl2policy.policy.optimize import EVAL_SEED
        from nl2policy.policy.rollout import evaluate

        k = key(tree_json)
        if k not in self.cache:
            get_domain(DOMAIN)
            result = evaluate(DOMAIN, tree_act_fn(DOMAIN, tree_from_json(tree_json)), self.episodes, EVAL_SEED)
            self.cache[k] = result.returns
            with self.path.open("a") as f:
                f.write(json.dumps({"tree": k, "episodes": self.episodes, "returns": result.returns}) + "\n")
        return np.asarray(self.cache[k])


def starts(frequent: int, lowest: int) -> list[dict]:
    from nl2policy.domains import get_domain
    from experiments.policy.table2 import distinct_policies
    from nl2policy.policy.keep_best import tree_scorer
    from nl2policy.trees import parse_tree

    vocab, (score, _) = get_domain(DOMAIN).vocab, tree_scorer(DOMAIN)
    policies = distinct_policies(DOMAIN)
    chosen = [{"tree": t, "count": c, "group": "frequent", "rank": i} for i, (t, c) in enumerate(policies[:frequent])]
    rest = sorted(({"tree": t, "count": c, "twin": score(parse_tree(t, vocab))} for t, c in policies[frequent:]),
                  key=lambda p: p["twin"])
    return chosen + [dict(p, group="lowest", rank=i) for i, p in enumerate(rest[:lowest])]


def ceiling(out: Path, candidates: int, episodes: int) -> dict:
    """The best corpus tree on highway-env (module doc), cached in ceiling.json."""
    path = out / "ceiling.json"
    if path.is_file():
        return json.loads(path.read_text())
    from nl2policy.domains import get_domain
    from nl2policy.policy.convert import tree_batch_act_fn
    from experiments.policy.table2 import distinct_policies
    from nl2policy.policy.rollout import evaluate_batched
    from nl2policy.trees import parse_tree

    vocab = get_domain(DOMAIN).vocab
    screened = sorted(((evaluate_batched(DOMAIN, tree_batch_act_fn(DOMAIN, parse_tree(t, vocab)), 500, CEILING_SEED).mean_return, t)
                       for t, _ in distinct_policies(DOMAIN)), key=lambda p: -p[0])
    judge = Judge(out / "judged.jsonl", episodes)
    rows = [{"tree": t, "twin_500": s, "highway_env": float(judge.returns(t).mean()),
             "stderr": float(judge.returns(t).std(ddof=1) / np.sqrt(episodes))} for s, t in screened[:candidates]]
    best = max(rows, key=lambda r: r["highway_env"])
    result = {"value": best["highway_env"], "tree": best["tree"], "episodes": episodes,
              "policies_screened": len(screened), "candidates": rows}
    path.write_text(json.dumps(result, indent=2))
    return result


def run_start(args: tuple) -> list[dict]:
    """Every seed of one start, in one process (the polish of a tree is computed once)."""
    start, seeds, steps, out, episodes, twin_episodes = args
    import torch

    from nl2policy.domains import get_domain
    from nl2policy.policy.optimize import CHECKPOINT, optimize_tree
    from nl2policy.policy.rollout import evaluate_batched
    from nl2policy.policy.sb3_policy import TreePPO
    from nl2policy.trees import parse_tree

    from nl2policy.policy.convert import tree_batch_act_fn
    from nl2policy.policy.keep_best import tree_from_json

    torch.set_num_threads(1)
    judge = Judge(out / f"judged_{start['group']}{start['rank']:02d}.jsonl", episodes)
    rows = []
    for seed in range(seeds):
        run_dir = out / "runs" / f"{start['group']}{start['rank']:02d}_s{seed}"
        done = run_dir / "run.json"
        if done.is_file():
            rows.append(json.loads(done.read_text()))
            continue
        begin = time.perf_counter()
        summary = optimize_tree(DOMAIN, parse_tree(start["tree"], get_domain(DOMAIN).vocab), steps, seed, run_dir)
        seconds = time.perf_counter() - begin
        model = TreePPO.load(run_dir / CHECKPOINT, device="cpu")
        soft = evaluate_batched(DOMAIN, lambda obs: model.predict(obs, deterministic=False)[0], twin_episodes, GAP_SEED).returns
        trees = {stage: json.loads((run_dir / f"{stage}_tree.json").read_text())
                 for stage in ("initial", "last", "best", "final")}
        last_twin = evaluate_batched(DOMAIN, tree_batch_act_fn(DOMAIN, tree_from_json(trees["last"])), twin_episodes,
                                     GAP_SEED).returns
        row = {"group": start["group"], "rank": start["rank"], "seed": seed, "count": start["count"],
               "tree": start["tree"], "seconds": seconds, "summary": summary, "trees": trees,
               "judged": {stage: float(judge.returns(t).mean()) for stage, t in trees.items()},
               "paired_stderr": {stage: float((judge.returns(t) - judge.returns(trees["initial"])).std(ddof=1) / np.sqrt(episodes))
                                 for stage, t in trees.items()},
               "soft_vs_discrete_twin": float(np.mean(last_twin) - np.mean(soft))}
        done.write_text(json.dumps(row))
        for bulky in ("checkpoint.zip", "state.json", "curve.png"):
            (run_dir / bulky).unlink(missing_ok=True)
        rows.append(row)
        print(f"{run_dir.name}: {row['judged']['initial']:.2f} -> {row['judged']['final']:.2f} "
              f"({summary['returned']}) {seconds:.1f} s", flush=True)
    return rows


STAGES = {"last": "PPO's last tree", "best": "keep-best (no polish)", "final": "returned (keep-best + polish)"}


def summarize(rows: list[dict], best: float) -> dict:
    out = {}
    for stage, label in STAGES.items():
        pairs = [(r["judged"][stage], r["judged"]["initial"], r["paired_stderr"][stage]) for r in rows]
        gaps = [(v - s) / (best - s) for v, s, _ in pairs if best - s > 1e-9]
        out[stage] = {"label": label, "runs": len(pairs),
                      "never_worse": sum(v >= s for v, s, _ in pairs),
                      "never_worse_within_noise": sum(v >= s - 2 * se for v, s, se in pairs),
                      "better": sum(v > s + 2 * se for v, s, se in pairs),
                      "within_1pct_of_best_corpus_tree": sum(v >= 0.99 * best for v, _, _ in pairs),
                      "median_gap_closed": statistics.median(gaps) if gaps else None,
                      "median_return": statistics.median(v for v, _, _ in pairs)}
    seconds = [r["seconds"] for r in rows]
    out["seconds_per_run"] = {"median": statistics.median(seconds), "max": max(seconds), "mean": statistics.fmean(seconds)}
    gaps = [r["soft_vs_discrete_twin"] for r in rows]
    out["soft_vs_discrete_gap_twin"] = {"median": statistics.median(gaps), "values": gaps}
    return out


def write(rows: list[dict], top: dict, settings: dict, out: Path, command: str) -> Path:
    from nl2policy.report import provenance

    meta, table, n, best = provenance(command), summarize(rows, top["value"]), len(rows), top["value"]
    lines = ["# Highway: `nl2policy optimize` from many starts, judged on highway-env", "",
             f"Made by: `{command}`  ", f"On: {meta['made']}  ", f"Settings: {json.dumps(settings)}", "",
             f"Best corpus tree on highway-env ({top['episodes']} episodes, the best of the {len(top['candidates'])} "
             f"best of {top['policies_screened']} distinct corpus policies on 500 twin scenes): {best:.3f}; within 1 % "
             f"means >= {0.99 * best:.3f}. Every tree below is judged on the same {settings['episodes']} highway-env "
             "episodes (seeds 50,000 on); a difference's standard error is paired. Gap closed = (tree - start) / "
             "(best corpus tree - start).", "",
             "| tree | runs | never worse | never worse within 2 se | better by 2 se | within 1 % of best corpus tree | median gap closed | median return |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for stage in STAGES:
        e = table[stage]
        gap = "-" if e["median_gap_closed"] is None else f"{e['median_gap_closed']:.3f}"
        lines.append(f"| {e['label']} | {e['runs']} | {e['never_worse']}/{n} | {e['never_worse_within_noise']}/{n} | "
                     f"{e['better']}/{n} | {e['within_1pct_of_best_corpus_tree']}/{n} | {gap} | {e['median_return']:.3f} |")
    s, g = table["seconds_per_run"], table["soft_vs_discrete_gap_twin"]
    lines += ["", f"Seconds per run (PPO on the twin, keep-best, polish; one thread a run, a shared 2-core machine): "
                  f"median {s['median']:.1f}, mean {s['mean']:.1f}, max {s['max']:.1f}. A start's second seed reuses "
                  "the polish of a kept tree the first seed already polished (the same tree polishes the same way).",
              f"Soft-vs-discrete gap (PPO's last discretized tree minus the soft DDT, sampling, "
              f"{settings['twin_episodes']} twin scenes each): median {g['median']:+.3f}.",
              "", "Per run (mean highway-env return; last = PPO's last discretized tree, kept = keep-best, returned = after polish):", "",
              "| start | seed | count | start | last | kept | returned | returned by | returned - start (se) | soft-vs-discrete | seconds |",
              "|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|"]
    for r in rows:
        j = r["judged"]
        lines.append(f"| {r['group']} #{r['rank']} | {r['seed']} | {r['count']} | {j['initial']:.3f} | {j['last']:.3f} | "
                     f"{j['best']:.3f} | {j['final']:.3f} | {r['summary']['returned']} | "
                     f"{j['final'] - j['initial']:+.3f} ({r['paired_stderr']['final']:.3f}) | "
                     f"{r['soft_vs_discrete_twin']:+.3f} | {r['seconds']:.1f} |")
    md = out / "never_worse_highway.md"
    md.write_text("\n".join(lines) + "\n")
    (out / "never_worse_highway.json").write_text(json.dumps({"meta": meta, "settings": settings, "best_corpus_tree": top,
                                                              "table": table, "runs": rows}, indent=2))
    return md


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--steps", type=int, default=50_000)
    parser.add_argument("--starts", type=int, nargs=2, default=(7, 3), metavar=("FREQUENT", "LOWEST"))
    parser.add_argument("--episodes", type=int, default=200, help="highway-env episodes judging each tree")
    parser.add_argument("--twin-episodes", type=int, default=500, help="twin scenes for the soft-vs-discrete gap")
    parser.add_argument("--ceiling-candidates", type=int, default=3)
    parser.add_argument("--ceiling-episodes", type=int, default=500)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("results/policy/never_worse_highway"))
    args = parser.parse_args()
    command = (f"python experiments/highway_never_worse.py --seeds {args.seeds} --steps {args.steps} "
               f"--starts {args.starts[0]} {args.starts[1]} --episodes {args.episodes} --twin-episodes {args.twin_episodes} "
               f"--ceiling-candidates {args.ceiling_candidates} --ceiling-episodes {args.ceiling_episodes} "
               f"--workers {args.workers} --out {args.out}")
    args.out.mkdir(parents=True, exist_ok=True)
    chosen = starts(*args.starts)
    jobs = [(s, args.seeds, args.steps, args.out, args.episodes, args.twin_episodes) for s in chosen]
    with ProcessPoolExecutor(args.workers) as pool:
        top_future = pool.submit(ceiling, args.out, args.ceiling_candidates, args.ceiling_episodes)
        rows = [row for rows in pool.map(run_start, jobs) for row in rows]
        top = top_future.result()
    settings = {"starts": len(chosen), "seeds": list(range(args.seeds)), "steps": args.steps,
                "episodes": args.episodes, "twin_episodes": args.twin_episodes, "runs": len(rows)}
    print(write(rows, top, settings, args.out, command).read_text())


if __name__ == "__main__":
    sys.exit(main())
