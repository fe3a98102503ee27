"""``python -m experiments.policy fidelity``: the fidelity claim's numbers, written to results/policy/fidelity.md."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.language.corpus import distinct_trees
from nl2policy.policy.fidelity import agreement, env_states, round_trips, uniform_states
from nl2policy.report import provenance


def write_fidelity(states: int, out: Path, command: str, domains: tuple[str, ...] = DOMAINS) -> Path:
    """Writes fidelity.md/.json for all domains, or fidelity_<domains>.md/.json for a subset
    (so re-checking one domain after changing its settings leaves the other's record alone)."""
    meta = provenance(command)
    leaf_mass = {domain: get_domain(domain).knobs.leaf_mass for domain in DOMAINS}
    report: dict = {"meta": meta, "states": states, "leaf_mass": leaf_mass, "domains": {}}
    lines = ["# Fidelity of the fresh (tree-initialized) DDT", "", f"Made by: `{command}`  ", f"On: {meta['made']}", "",
             f"Agreement = fraction of {states} sampled states on which the DDT's most likely action is the tree's "
             f"action; min and mean over every distinct corpus tree. Leaf mass (per domain): {json.dumps(leaf_mass)}. "
             "Env states: rolled with random actions (seed 0); uniform: see `policy/fidelity.py`.", "",
             "| domain | trees | gamma | states | padded | min agreement | mean agreement | trees below 99.9 % |",
             "|---|---:|---:|---|---|---:|---:|---:|"]
    for domain in domains:
        trees = distinct_trees(domain)
        samples = {"env": env_states(domain, states, seed=0), "uniform": uniform_states(domain, states, seed=0)}
        rows = []
        used = get_domain(domain).knobs.ddt_gamma
        for gamma in (used, *get_domain(domain).knobs.fidelity_gammas):
            for kind, X in samples.items():
                for pad in ((False, True) if gamma == used else (False,)):
                    values = np.array([agreement(domain, t, X, pad=pad, gamma=gamma) for t in trees])
                    rows.append({"gamma": gamma, "states": kind, "padded": pad, "min": float(values.min()),
                                 "mean": float(values.mean()), "below_999": int((values < 0.999).sum())})
                    lines.append(f"| {domain} | {len(trees)} | {gamma:g}{' (used)' if gamma == used else ''} | {kind} | "
                                 f"{'yes' if pad else 'no'} | {values.min():.4f} | {values.mean():.5f} | {rows[-1]['below_999']} |")
        trips = sum(round_trips(domain, t) for t in trees)
        trips_padded = sum(round_trips(domain, t, pad=True) for t in trees)
        report["domains"][domain] = {"trees": len(trees), "gamma": used, "rows": rows,
                                     "round_trips": trips, "round_trips_padded": trips_padded}
    lines += ["", "Discretizing the fresh DDT gives back the same tree (structural equality):", ""]
    for domain, r in report["domains"].items():
        lines.append(f"- {domain}: {r['round_trips']}/{r['trees']} trees; padded to the 15-slot grid first: "
                     f"{r['round_trips_padded']}/{r['trees']}")
    out.mkdir(parents=True, exist_ok=True)
    stem = "fidelity" if tuple(domains) == tuple(DOMAINS) else "fidelity_" + "_".join(domains)
    (out / f"{stem}.json").write_text(json.dumps(report, indent=2))
    md = out / f"{stem}.md"
    md.write_text("\n".join(lines) + "\n")
    return md
