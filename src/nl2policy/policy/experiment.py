"""The paper's Table 2: tree-initialized DDT vs random DDT (8 leaves) vs MLP, under PPO.

Protocol: the `candidates` most frequent distinct corpus trees are ranked by the tree's own
mean return (`select_episodes` episodes); the best `best` are the tree-DDT starts, each trained
with `tree_seeds` seeds; each baseline gets `baseline_seeds` seeds. Metric: rolling mean of
training episode reward (window ``Knobs.rolling_window``): *initial* = the mean of the first window,
*best* = the highest rolling mean over the run once a full window exists. Reported: median and
standard error (std / sqrt(runs)) across runs. Every run has its own folder with a
checkpoint and, when done, ``result.json``; a restarted experiment skips finished runs and
resumes unfinished ones, so a killed highway grid loses at most one checkpoint chunk.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from nl2policy.language.corpus import load_corpus
from nl2policy.policy.convert import ddt_to_tree, has_raw_tests, tree_act_fn
from nl2policy.policy.optimize import EVAL_SEED, checkpoint_tree_score, rolling_mean, train_checkpointed, write_curve
from nl2policy.policy.rollout import evaluate, tree_policy
from nl2policy.policy.sb3_policy import METHODS, actor_ddt, make_ppo, soft_act_fn
from nl2policy.trees import parse_tree, tree_to_json
from nl2policy.domains import get_domain

LABEL = {"tree_ddt": "tree-initialized DDT", "random_ddt": "random DDT (8 leaves)", "mlp": "MLP (3 layers)"}


def distinct_policies(domain: str) -> list[tuple[dict, int]]:
    """Corpus trees grouped by the policy they encode (``Domain.same_policy``): one entry per
    distinct policy, (its most frequent spelling, how many specs encode it), most frequent
    first. Ranking policies rather than spellings keeps five rewordings of one policy from
    filling the best five."""
    d = get_domain(domain)
    spellings = Counter(json.dumps(tree_to_json(s.tree), sort_keys=True) for s in load_corpus(domain))
    groups: list[list] = []  # [representative tree, total count, best spelling count]
    for key, count in spellings.most_common():
        tree = parse_tree(json.loads(key), d.vocab)
        group = next((g for g in groups if d.same_policy(g[0], tree)), None)
        if group is None:
            groups.append([tree, count])
        else:
            group[1] += count
    groups.sort(key=lambda g: -g[1])  # stable: ties keep the most frequent spelling first
    return [(tree_to_json(tree), count) for tree, count in groups]


def select_trees(domain: str, candidates: int, best: int, episodes: int, seed: int, out: Path) -> list[dict]:
    """The `best` of the `candidates` most frequent distinct corpus policies, ranked by mean
    return over `episodes` episodes (with an exact model, taxi: by the exact expected return). Cached in out."""
    path = out / "selected_trees.json"
    if path.is_file():
        return json.loads(path.read_text())["selected"]
    vocab, exact = get_domain(domain).vocab, get_domain(domain).exact
    ranked = []
    for tree_json, count in distinct_policies(domain)[:candidates]:
        tree = parse_tree(tree_json, vocab)
        ev = evaluate(domain, tree_policy(domain, tree), episodes, seed)
        entry = {"tree": tree_json, "count": count, "mean_return": ev.mean_return, "stderr": ev.stderr}
        if exact is not None:
            entry["exact_return"] = exact.expected_return(tree_act_fn(domain, tree))
        ranked.append(entry)
    ranked.sort(key=lambda r: -r.get("exact_return", r["mean_return"]))
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"episodes": episodes, "seed": seed, "grouped_by": "distinct policy (Domain.same_policy)",
                                "ranked_by": "exact_return" if exact is not None else "mean_return",
                                "candidates": ranked, "selected": ranked[:best]}, indent=2))
    return ranked[:best]


def run_one(domain: str, method: str, seed: int, steps: int, run_dir: Path, tree_json: Optional[dict],
            progress: Optional[Callable[[int, int], None]] = None) -> dict:
    result_path = run_dir / "result.json"
    if result_path.is_file():
        return json.loads(result_path.read_text())
    d = get_domain(domain)
    tree = parse_tree(tree_json, d.vocab) if tree_json else None
    score = checkpoint_tree_score(domain) if method != "mlp" else None
    model, episodes, seconds, best = train_checkpointed(lambda: make_ppo(domain, method, seed, tree), domain, seed,
                                                        steps, run_dir, progress, score)
    window = d.knobs.rolling_window
    write_curve(episodes, window, run_dir, f"{domain}: {LABEL[method]} seed {seed}")
    rolling = rolling_mean([r for _, r in episodes], window)
    full = rolling[window - 1:] if len(rolling) >= window else rolling[-1:]
    result = {"domain": domain, "method": method, "seed": seed, "steps": int(model.num_timesteps),
              "seconds": seconds, "episodes": len(episodes), "window": window, "tree": tree_json,
              "initial": float(full[0]), "best": float(full.max()), "final": float(rolling[-1]),
              "curve": [[s, float(m)] for (s, _), m in zip(episodes, rolling)]}
    if d.exact is not None:  # what the user gets back, judged exactly: the discretized tree (greedy MLP)
        final_act = (tree_act_fn(domain, ddt_to_tree(domain, actor_ddt(model))) if method != "mlp"
                     else soft_act_fn(model, deterministic=True))
        result["exact_final"] = d.exact.expected_return(final_act)
        if tree is not None:
            result["exact_initial_tree"] = d.exact.expected_return(tree_act_fn(domain, tree))
        if best is not None:  # the best discretized tree over the run's checkpoints (exact score)
            result.update({"exact_best_tree": best["score"], "best_tree_step": best["step"], "best_tree": best["tree"]})
    if method == "tree_ddt":  # how far is the discretized tree from the soft DDT it came from?
        final_tree = ddt_to_tree(domain, actor_ddt(model))
        n = d.knobs.eval_episodes
        result.update({
            "final_tree": tree_to_json(final_tree), "final_tree_has_raw_tests": has_raw_tests(final_tree),
            "eval_episodes": n,
            "eval_soft_ddt": evaluate(domain, soft_act_fn(model, False), n, EVAL_SEED).mean_return,
            "eval_discretized": evaluate(domain, tree_act_fn(domain, final_tree), n, EVAL_SEED).mean_return,
            "eval_initial_tree": evaluate(domain, tree_policy(domain, tree), n, EVAL_SEED).mean_return,
        })
    result_path.write_text(json.dumps(result))
    (run_dir / "checkpoint.zip").unlink(missing_ok=True)  # finished: result.json is the record
    return result


def plan(selected: list[dict], tree_seeds: int, baseline_seeds: int) -> list[tuple[str, str, int, Optional[dict]]]:
    """(run name, method, seed, tree) for every run of the grid."""
    runs = [(f"tree_ddt_t{k}_s{s}", "tree_ddt", s, sel["tree"]) for k, sel in enumerate(selected) for s in range(tree_seeds)]
    for method in ("random_ddt", "mlp"):
        runs += [(f"{method}_s{s}", method, s, None) for s in range(baseline_seeds)]
    return runs


def summarize(results: list[dict], domain: str) -> dict:
    table = {}
    for method in METHODS:
        rows = [r for r in results if r["method"] == method]
        if not rows:
            continue
        entry = {"runs": len(rows)}
        for key in ("initial", "best", "final"):
            values = np.array([r[key] for r in rows])
            entry[key] = {"median": float(np.median(values)),
                          "stderr": float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0}
        if "exact_final" in rows[0]:
            exact = np.array([r["exact_final"] for r in rows])
            entry["exact_final"] = {"median": float(np.median(exact)), "mean": float(exact.mean()),
                                    "stderr": float(exact.std(ddof=1) / np.sqrt(len(exact))) if len(exact) > 1 else 0.0}
        if "exact_best_tree" in rows[0]:
            best = np.array([r["exact_best_tree"] for r in rows])
            entry["exact_best_tree"] = {"median": float(np.median(best)), "mean": float(best.mean()),
                                        "stderr": float(best.std(ddof=1) / np.sqrt(len(best))) if len(best) > 1 else 0.0}
        if method == "tree_ddt" and "exact_initial_tree" in rows[0]:
            for name, key in (("exact_gain", "exact_final"), ("exact_best_gain", "exact_best_tree")):
                gain = np.array([r[key] - r["exact_initial_tree"] for r in rows])
                entry[name] = {"median": float(np.median(gain)), "mean": float(gain.mean()),
                               "improved": int((gain > 1e-9).sum()), "worse": int((gain < -1e-9).sum())}
        if method == "tree_ddt":
            gaps = [r["eval_discretized"] - r["eval_soft_ddt"] for r in rows]
            entry["discretized_minus_soft"] = {"mean": float(np.mean(gaps)), "values": gaps}
            entry["raw_test_trees"] = sum(r["final_tree_has_raw_tests"] for r in rows)
        table[method] = entry
    exact = get_domain(domain).exact
    if exact is not None:
        optimum = exact.optimum()
        for entry in table.values():
            for key in ("initial", "best", "final", "exact_final", "exact_best_tree"):
                if key in entry:
                    entry[key]["percent_of_optimal"] = 100.0 * entry[key]["median"] / optimum
        table["optimal_return"] = optimum
    return table
