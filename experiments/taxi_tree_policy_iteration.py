"""What the critic's reading could do with a perfect critic: exact policy iteration over taxi trees.

``nl2policy.policy.advantage`` reads, at each checkpoint, the dictionary tree that PPO's critic
says gains most over the policy being trained (the first-order term of the performance-difference
lemma, estimated from GAE advantages), and ``adopt_read_tree`` lets PPO continue from it. This
command asks how far that step can go at all. On the exact taxi model it computes, for a tree's
stationary policy, the occupancy-weighted advantages exactly (the shift's ticks included:
A(s, a) = sum_t P(at state s at tick t) * (Q_t(s, a) - V_t(s))), fits the best tree of depth <= 3
to them (``distill.fit_tree_scores``, exact), and repeats from that tree. So every number here is
the critic step without sampling noise or critic error, from issue 45's weak starts and Table 2's
corpus starts: the 15 most frequent distinct corpus policies, the weak starts among them marked.

Run: ``.venv/bin/python -m experiments.taxi_tree_policy_iteration --out results/policy``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from nl2policy.domains import get_domain
from nl2policy.domains.taxi.ceilings import best_tree
from nl2policy.domains.taxi.tables import TaxiTables, taxi_tables
from nl2policy.policy.distill import fit_tree_scores
from nl2policy.report import provenance
from nl2policy.trees import Tree, parse_tree, tree_to_json
from experiments.taxi_never_worse import starts, weak_starts

ITERATIONS = 8


def occupancy_advantages(tables: TaxiTables, policy: np.ndarray) -> tuple[np.ndarray, float]:
    """(A: feature states x actions, the policy's exact return) for a stationary policy (an action
    index per feature state): A(s, a) = sum over ticks of P(s at t) * (Q_t(s, a) - V_t(s))."""
    horizon, longest, n = tables.model.shift_ticks, int(tables.ticks.max()), tables.n_states
    states = np.arange(n)
    values = np.zeros((horizon + longest + 1, n))
    q = np.zeros((horizon, n, tables.ticks.shape[1]))
    for t in range(horizon - 1, -1, -1):
        future = values[t + tables.ticks, :]  # (S, A, S): V at each action's arrival tick
        q[t] = np.where(t + tables.ticks <= horizon, tables.reward + np.einsum("sak,sak->sa", tables.next_prob, future), 0.0)
        values[t] = q[t][states, policy]
    at = np.zeros((horizon + longest + 1, n))
    at[0] = tables.initial
    for t in range(horizon):
        arrive = t + tables.ticks[states, policy]
        for s in np.flatnonzero(at[t]):
            if arrive[s] <= horizon:
                at[arrive[s]] += at[t, s] * tables.next_prob[s, policy[s]]
    advantages = np.einsum("ts,tsa->sa", at[:horizon], q - values[:horizon, :, None])
    return advantages, float(values[0] @ tables.initial)


def iterate(tree: Tree, tables: TaxiTables, iterations: int = ITERATIONS) -> list[tuple[Tree, float]]:
    """[(tree, exact return)] from the start through `iterations` exact critic steps."""
    d = get_domain("taxi")
    X = tables.features()
    answers = d.answer_matrix(X)
    path = []
    for _ in range(iterations + 1):
        policy = d.tree_actions(tree, X)
        advantages, value = occupancy_advantages(tables, policy)
        path.append((tree, value))
        # ties between equal advantages keep the tree's own action (the reading's tie-break)
        tree = fit_tree_scores(answers, advantages + 1e-9 * np.eye(advantages.shape[1])[policy],
                               list(d.questions), list(d.actions))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/policy"))
    args = parser.parse_args()
    d = get_domain("taxi")
    tables = taxi_tables()
    ceiling = best_tree(tables, depth=3).value
    weak = {s["rank"] for s in weak_starts()}
    chosen = [dict(s, label=f"#{s['rank']}" + (" (weak start)" if s["rank"] in weak else "")) for s in starts(15, lowest=0)]
    rows = []
    for start in chosen:
        path = iterate(parse_tree(start["tree"], d.vocab), tables)
        values = [v for _, v in path]
        rows.append({"start": start["label"], "count": start["count"], "returns": values, "best": max(values),
                     "best_tree": tree_to_json(max(path, key=lambda p: p[1])[0])})
    command = "python -m experiments.taxi_tree_policy_iteration" + (f" --out {args.out}" if args.out != Path("results/policy") else "")
    record = {**provenance(command), "iterations": ITERATIONS, "best_depth3_tree": ceiling, "rows": rows}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "tree_policy_iteration_taxi.json").write_text(json.dumps(record, indent=2))
    lines = [
        "# Taxi: exact policy iteration over trees (the critic's step with a perfect critic)", "",
        f"Made by: `{command}`  ", f"On: {record['made']}", "",
        "From each start, the tree of depth <= 3 that maximizes the exact occupancy-weighted advantage of the "
        "current tree's policy, repeated (module doc of `experiments/taxi_tree_policy_iteration.py`). Returns are "
        f"exact. The best depth-3 dictionary tree returns {ceiling:.4f}; the best depth-2 tree 7.9399.", "",
        "| start | corpus count | returns, start first | best | >= 8.0 |", "|---|---:|---|---:|---|",
    ]
    for r in rows:
        lines.append(f"| {r['start']} | {r['count']} | {', '.join(f'{v:.3f}' for v in r['returns'])} | {r['best']:.4f} | "
                     f"{'yes' if r['best'] >= 8.0 else 'no'} |")
    reached = sum(r["best"] >= 8.0 for r in rows)
    lines += ["", f"Starts whose iterates reach 8.0: {reached} of {len(rows)}; reach the best depth-3 tree "
              f"(within 1e-6): {sum(r['best'] >= ceiling - 1e-6 for r in rows)} of {len(rows)}."]
    (args.out / "tree_policy_iteration_taxi.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
