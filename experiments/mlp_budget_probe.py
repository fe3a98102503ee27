"""Where does the MLP baseline plateau? One PPO run of Table 2's MLP, probed as Table 2 probes it.

Issue 27 asks Table 2 to give every method enough steps for the MLP to plateau. This runs the
grid's own `run_one` for the MLP (same PPO settings, same probe: the greedy policy scored
exactly on taxi, on ``probe_episodes`` common twin scenes on highway) for a long budget and
writes the probes and the rolling training reward, so the table's budget is read off a curve
and not guessed. Resumable (the run's checkpoint); `--summarize-only` writes the file from an
unfinished run's state.json.

    PYTHONPATH=src:. .venv/bin/python experiments/mlp_budget_probe.py --domain highway --steps 600000 \
        --out results/policy/mlp_budget_highway
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from nl2policy.domains import get_domain
from experiments.policy.table2 import probe_rule, run_one
from nl2policy.policy.optimize import rolling_mean


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", default="highway")
    parser.add_argument("--steps", type=int, default=600_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--summarize-only", action="store_true", help="write the summary from the run as it stands")
    args = parser.parse_args()
    torch.set_num_threads(1)
    run_dir = args.out / "run"
    started = time.time()
    if not args.summarize_only:
        run_one(args.domain, "mlp", args.seed, args.steps, run_dir, None)
    record_path = run_dir / ("result.json" if (run_dir / "result.json").is_file() else "state.json")
    if not record_path.is_file():
        raise SystemExit(f"error: no run in {run_dir} to summarize (run without --summarize-only first)")
    record = json.loads(record_path.read_text())
    window = get_domain(args.domain).knobs.rolling_window
    if isinstance(record["episodes"], list):  # state.json: every episode's (step, reward); run_one's rolling mean
        rolling = rolling_mean([r for _, r in record["episodes"]], window)
        curve = [(s, float(m)) for (s, _), m in zip(record["episodes"], rolling)]
    else:  # result.json: that rolling mean already, one point per episode
        curve = record["curve"]
    rolling_at = curve[window - 1:]  # full windows only
    lines = [f"# MLP budget probe ({args.domain})", "",
             f"Made by: `PYTHONPATH=src:. .venv/bin/python experiments/mlp_budget_probe.py --domain {args.domain} "
             f"--steps {args.steps} --seed {args.seed} --out {args.out}`" + (" (then `--summarize-only`)" if args.summarize_only else ""),
             f"Run: {record['steps']} of {args.steps} steps ({'finished' if record_path.name == 'result.json' else 'stopped there'}), "
             f"seed {args.seed}; probes scored: {probe_rule(args.domain)}", "",
             f"| step | greedy policy (probe) | soft policy (probe) | rolling training reward ({window} episodes) |",
             "|---:|---:|---:|---:|"]
    for p in record["probes"]:
        before = [m for s, m in rolling_at if s <= p["step"]]
        rolling = f"{before[-1]:.3f}" if before else "-"
        lines.append(f"| {p['step']} | {p['policy']:.3f} | {p['soft']:.3f} | {rolling} |")
    lines += ["", f"Wall seconds of this invocation: {time.time() - started:.0f}"]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "probe.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
