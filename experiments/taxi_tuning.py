"""Does PPO change the tree? Old vs new taxi settings, judged by the EXACT return of the tree.

Run as ``python -m experiments.taxi_tuning [--steps N] [--seeds K] [--out DIR]``: for three
corpus policies of different quality (good, median, poor) and each settings variant, PPO
from the tree-initialized DDT; after every ``CHUNK`` steps the DDT is discretized and the
tree's exact expected return (``domains.taxi.expected_return``) recorded. Writes
``tuning_taxi.md`` / ``.json``. One thread; runs are short (taxi ~600 steps/s per core).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import torch

from nl2policy.domains import get_domain
from nl2policy.domains.spec import Knobs
from nl2policy.domains.taxi.env import TaxiModel, expected_return, optimal_policy
from nl2policy.policy.convert import ddt_to_tree, tree_act_fn
from nl2policy.policy.sb3_policy import make_ppo
from nl2policy.report import provenance
from nl2policy.trees import parse_tree

CHUNK = 5120
TREES = {  # exact returns 7.94 / 6.206 / 4.867; the 1st, 2nd and 14th most frequent corpus policies
    "good": {"if": "has_passenger", "yes": {"do": "go_airport"},
             "no": {"if": "heavy_traffic", "yes": {"do": "go_village"}, "no": {"do": "go_city"}}},
    "median": {"if": "has_passenger", "yes": {"do": "go_airport"},
               "no": {"if": "at_city", "yes": {"do": "wait"}, "no": {"do": "go_city"}}},
    "poor": {"if": "at_village", "yes": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "wait"}},
             "no": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_village"}}},
}
# The settings before this sweep (PPO's 3e-4 for the tree, leaf mass 0.95, no entropy bonus)
# and the ones now in taxi/spec.toml's knobs.
VARIANTS = {
    "old: lr x1, mass 0.95, ent 0": dict(scale=1.0, mass=0.95, ent_coef=0.0),
    "new: lr x33, mass 0.7, ent 0.01": dict(scale=33.0, mass=0.7, ent_coef=0.01),
}


def variant_knobs(variant: dict) -> Knobs:
    """Taxi's knobs with the variant's leaf mass, actor lr scale and entropy bonus."""
    knobs = get_domain("taxi").knobs
    return dataclasses.replace(knobs, leaf_mass=variant["mass"], actor_lr_scale=variant["scale"],
                               ppo=dataclasses.replace(knobs.ppo, ent_coef=variant["ent_coef"]))


def run(variant: dict, tree_json: dict, seed: int, steps: int) -> dict:
    """One PPO run under `variant`; the exact return of the discretized tree after every chunk."""
    model_ = TaxiModel()
    tree = parse_tree(tree_json, get_domain("taxi").vocab)
    model = make_ppo("taxi", "tree_ddt", seed, tree, knobs=variant_knobs(variant))
    start, trajectory = time.perf_counter(), []
    while model.num_timesteps < steps:
        model.learn(CHUNK, reset_num_timesteps=False)
        final = ddt_to_tree("taxi", model.policy.action_net)
        trajectory.append(expected_return(model_, tree_act_fn("taxi", final)))
    return {"initial": expected_return(model_, tree_act_fn("taxi", tree)), "trajectory": trajectory,
            "seconds": time.perf_counter() - start}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30720)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("results/policy"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    command = f"python -m experiments.taxi_tuning --steps {args.steps} --seeds {args.seeds} --out {args.out}"
    optimum = optimal_policy(TaxiModel())[0]
    rows = []
    for label, variant in VARIANTS.items():
        for name, tree_json in TREES.items():
            for seed in range(args.seeds):
                r = run(variant, tree_json, seed, args.steps)
                rows.append({"variant": label, "tree": name, "seed": seed, **r})
                print(json.dumps(rows[-1]), flush=True)
    meta = provenance(command)
    lines = ["# Does PPO change the tree? (taxi, exact returns of the discretized tree)", "",
             f"Made by: `{command}`  ", f"On: {meta['made']}  ",
             f"Discretized after every {CHUNK} steps; exact expected return (`domains.taxi.expected_return`). "
             f"Optimum {optimum:.3f}. Other PPO settings: taxi/spec.toml's `[knobs.ppo]`.", "",
             "| variant | tree | seed | initial tree | final tree | best checkpoint tree | trajectory |",
             "|---|---|---:|---:|---:|---:|---|"]
    for r in rows:
        traj = " ".join(f"{v:.2f}" for v in r["trajectory"])
        lines.append(f"| {r['variant']} | {r['tree']} | {r['seed']} | {r['initial']:.3f} | {r['trajectory'][-1]:.3f} | "
                     f"{max([r['initial'], *r['trajectory']]):.3f} | {traj} |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "tuning_taxi.json").write_text(json.dumps({"meta": meta, "variants": VARIANTS, "runs": rows}, indent=2))
    (args.out / "tuning_taxi.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
