"""``nl2policy ceilings``: a domain's yardsticks, written to results/policy/ceilings_<domain>.md/.json.

For a domain with an exact model in feature-state form (taxi): the optimum (value iteration,
the tick seen), the best stationary policy on the features and the best dictionary trees of
depth <= 1, 2 and 3, each found by the exact searches of ``ceilings`` (why each is the
maximum: that module's doc), beside the best corpus tree on the same exact model.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

from nl2policy.domains import get_domain
from nl2policy.language.corpus import distinct_trees
from nl2policy.policy.rollout import tree_policy
from nl2policy.report import provenance
from nl2policy.trees import parse_tree, to_text, tree_to_json

from .ceilings import Ceiling, best_stationary_policy, best_tree

ACTION_NAMES = ("go_airport", "go_village", "go_city", "wait")


def compute_ceilings(domain: str, max_depth: int = 3, progress: Optional[Callable[[str], None]] = None) -> dict:
    """Every ceiling of `domain` as a JSON-ready dict (see module doc). ValueError where the
    domain has no exact model to search on."""
    d = get_domain(domain)
    if d.exact is None or not hasattr(d.exact, "tables"):
        # highway's ceilings (a plateaued MLP, the best corpus tree on 500+ episodes) are not built yet
        raise ValueError(f"ceilings need an exact model to search; {domain} has none")
    tables = d.exact.tables()
    corpus = [(t, d.exact.expected_return(tree_policy(domain, t))) for t in distinct_trees(domain)]
    best_corpus, best_corpus_value = max(corpus, key=lambda tv: tv[1])
    optimum = d.exact.optimum()
    if progress:
        progress("optimum and corpus trees done")
    stationary = best_stationary_policy(tables, progress=progress)
    trees = {depth: best_tree(tables, depth, progress=progress) for depth in range(1, max_depth + 1)}
    reach = tables.reachable()

    def tree_entry(c: Ceiling) -> dict:
        return {"value": c.value, "percent_of_optimum": 100 * c.value / optimum, "tree": tree_to_json(c.tree),
                "counts": c.counts, "seconds": c.seconds}

    return {
        "domain": domain, "optimum": optimum,
        "reachable_feature_states": len(reach), "feature_states": tables.n_states,
        "best_corpus_tree": {"value": best_corpus_value, "percent_of_optimum": 100 * best_corpus_value / optimum,
                             "tree": tree_to_json(best_corpus), "distinct_corpus_trees": len(corpus)},
        "best_stationary_policy": {
            "value": stationary.value, "percent_of_optimum": 100 * stationary.value / optimum,
            "counts": stationary.counts, "seconds": stationary.seconds,
            "policy": [{"features": dict(zip(d.features, map(int, tables.states[s].features()))),
                        "action": ACTION_NAMES[stationary.policy[s]]} for s in reach]},
        "best_trees": {str(depth): tree_entry(c) for depth, c in trees.items()},
    }


def write_ceilings(result: dict, out: Path, command: str) -> Path:
    meta = provenance(command)
    domain, opt = result["domain"], result["optimum"]
    vocab = get_domain(domain).vocab
    st = result["best_stationary_policy"]
    lines = [f"# Ceilings ({domain}), exact", "", f"Made by: `{command}`  ", f"On: {meta['made']}", "",
             "Every value is an exact expected return on the exact model (no sampling). The searches are exhaustive "
             "branch and bound with an admissible bound (`src/nl2policy/domains/taxi/ceilings.py` says why each result "
             "is the maximum); counts say how much was looked at, seconds are on one core.", "",
             "| ceiling | return | % of optimum | searched | seconds |", "|---|---:|---:|---|---:|",
             f"| optimum (value iteration, the tick seen) | {opt:.4f} | 100.0 | - | - |",
             f"| best stationary policy on the features | {st['value']:.4f} | {st['percent_of_optimum']:.1f} | "
             f"{st['counts']['policies_in_space']:,} policies over {st['counts']['states_searched']} reachable feature "
             f"states, {st['counts']['bounds_computed']} bounds computed | {st['seconds']:.1f} |"]
    for depth, e in result["best_trees"].items():
        c = e["counts"]
        lines.append(f"| best dictionary tree, depth <= {depth} | {e['value']:.4f} | {e['percent_of_optimum']:.1f} | "
                     f"{c['trees_unrestricted']:,} trees; {c['pairs_in_space']:,} (root question, yes map, no map) "
                     f"candidates, {c['side_bounds_computed']:,} "
                     f"side bounds, {c['pairs_scored']:,} scored exactly | {e['seconds']:.1f} |")
    bc = result["best_corpus_tree"]
    lines += [f"| best corpus tree (of {bc['distinct_corpus_trees']} distinct) | {bc['value']:.4f} | "
              f"{bc['percent_of_optimum']:.1f} | - | - |", ""]
    for depth, e in result["best_trees"].items():
        lines += [f"Best tree of depth <= {depth}:", "", "```", to_text(parse_tree(e["tree"], vocab), vocab), "```", ""]
    lines += ["Best corpus tree:", "", "```", to_text(parse_tree(bc["tree"], vocab), vocab), "```", "",
              "Best stationary policy (reachable feature states):", "",
              "| " + " | ".join(st["policy"][0]["features"]) + " | action |",
              "|" + "---|" * (len(st["policy"][0]["features"]) + 1)]
    for row in st["policy"]:
        lines.append("| " + " | ".join(str(v) for v in row["features"].values()) + f" | {row['action']} |")
    out.mkdir(parents=True, exist_ok=True)
    md = out / f"ceilings_{domain}.md"
    md.write_text("\n".join(lines) + "\n")
    (out / f"ceilings_{domain}.json").write_text(json.dumps({"meta": meta, **result}, indent=2))
    return md
