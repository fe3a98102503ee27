"""A ceiling by search where there is no exact model: the sampled climb from several starts.

Taxi's ceilings are exact (its folder's ``ceilings_report``). A domain that only has a fast
simulator (highway's twin, lunar's side-by-side Box2D) cannot enumerate trees exactly, so its
yardstick is a lower bound: the sampled polish (``polish.polish_sampled``: single edits screened
on common scenes, moves confirmed by paired tests) climbs from every state-blind tree (one per
action) and from the domain's example tree, and the tree with the best confirmed return is the
ceiling. Choosing it on the confirmation scenes biases its return there upwards, so the table
reports every climbed tree again on Table 2's probe scenes (``select_episodes`` scenes of the
fast env from ``EVAL_SEED``, where Table 2 scores its yardsticks and handed-back trees), which
neither the climb nor the choice saw.

What it cannot tell: a tree no climb reaches (the climb is local, from a handful of starts) may
be better. The count of trees scored says how much was looked at.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable, Optional

from nl2policy.domains import get_domain
from nl2policy.trees import MAX_DEPTH, Leaf, Tree, parse_tree, to_text, tree_to_json


def starts(domain: str) -> list[tuple[str, Tree]]:
    """(name, tree) of every start: each state-blind tree, then the example tree if given."""
    d = get_domain(domain)
    out: list[tuple[str, Tree]] = [(f"always {a}", Leaf(a)) for a in d.actions]
    if d.example_tree is not None:
        out.append(("the example's tree", d.example_tree))
    return out


def compute_ceilings(domain: str, max_depth: int = MAX_DEPTH,
                     progress: Optional[Callable[[str], None]] = None, screen_episodes: Optional[int] = None,
                     select_episodes: Optional[int] = None, eval_episodes: Optional[int] = None) -> dict:
    """Climb from every start (module doc); ValueError where the domain has no sampled polish or
    for a depth other than the grid's (the polish's edits keep trees within it). The episode
    counts default to the knobs' (``polish_screen_episodes``, ``select_episodes``, and
    ``select_episodes`` again for the fresh scenes, as Table 2's probe)."""
    from nl2policy.policy.convert import tree_batch_act_fn
    from nl2policy.policy.optimize import EVAL_SEED
    from nl2policy.policy.polish import polish_sampled
    from nl2policy.policy.rollout import evaluate_batched, reference_batch_act

    d = get_domain(domain)
    if max_depth != MAX_DEPTH:
        raise ValueError(f"a sampled ceiling climbs trees of the grid's depth ({MAX_DEPTH}) only")
    if d.train_env_id is None or not d.knobs.polish_screen_episodes or not d.knobs.select_episodes:
        raise ValueError(f"{domain} has neither an exact ceiling search nor a fast simulator to climb on")
    episodes = int(eval_episodes or d.knobs.select_episodes)
    screen_n = screen_episodes or d.knobs.polish_screen_episodes
    select_n = select_episodes or d.knobs.select_episodes
    climbs, began, todo = [], time.perf_counter(), starts(domain)
    for i, (name, start) in enumerate(todo):
        if progress:
            progress(f"{domain}: climbing from {name} ({i + 1}/{len(todo)})")
        polished = polish_sampled(domain, start, screen_n, select_n)
        fresh = {}
        for key, tree in (("start", start), ("climbed", polished.tree)):
            e = evaluate_batched(domain, tree_batch_act_fn(domain, tree), episodes, EVAL_SEED)
            fresh[key] = {"mean": e.mean_return, "stderr": e.stderr}
        climbs.append({"start_name": name, "start_tree": tree_to_json(start), "tree": tree_to_json(polished.tree),
                       "start_selection": polished.start_value, "selection": polished.value,
                       "accepted_moves": polished.rounds, "trees_scored": polished.candidates_scored,
                       "seconds": polished.seconds, "fresh_start": fresh["start"], "fresh": fresh["climbed"]})
    best = max(range(len(climbs)), key=lambda k: climbs[k]["selection"])
    reference = None
    if d.reference is not None:
        e = evaluate_batched(domain, reference_batch_act(domain), episodes, EVAL_SEED)
        reference = {"name": d.reference, "mean": e.mean_return, "stderr": e.stderr}
    return {"domain": domain, "max_depth": max_depth, "climbs": climbs, "best": best, "reference": reference,
            "eval_episodes": episodes, "eval_seed": EVAL_SEED, "screen_episodes": screen_n,
            "select_episodes": select_n, "seconds": time.perf_counter() - began}


def write_ceilings(result: dict, out: Path, command: str) -> Path:
    """ceilings_<domain>.md (one screen) and .json beside it."""
    from nl2policy.report import provenance

    meta = provenance(command)
    domain, vocab = result["domain"], get_domain(result["domain"]).vocab
    best = result["climbs"][result["best"]]
    lines = [f"# Ceiling ({domain}), by sampled search", "", f"Made by: `{command}`  ", f"On: {meta['made']}", "",
             f"A lower bound on the best depth-{result['max_depth']} dictionary tree: the sampled polish "
             f"(`src/nl2policy/policy/polish.py`) climbs from each start, screening every neighbour on "
             f"{result['screen_episodes']} common scenes and accepting only paired-test gains on "
             f"{result['select_episodes']} others; the best by that confirmation is the ceiling. *Fresh* is "
             f"{result['eval_episodes']} evaluation scenes (seed {result['eval_seed']}) that neither the climb nor "
             f"the choice saw, mean ± standard error. `src/nl2policy/policy/ceiling_climb.py` says what this cannot "
             f"tell.", "",
             "| start | fresh start | fresh climbed | accepted moves | trees scored | seconds |",
             "|---|---:|---:|---:|---:|---:|"]
    for k, c in enumerate(result["climbs"]):
        mark = " **(ceiling)**" if k == result["best"] else ""
        lines.append(f"| {c['start_name']}{mark} | {c['fresh_start']['mean']:.1f} ± {c['fresh_start']['stderr']:.1f} | "
                     f"{c['fresh']['mean']:.1f} ± {c['fresh']['stderr']:.1f} | {c['accepted_moves']} | "
                     f"{c['trees_scored']:,} | {c['seconds']:.0f} |")
    if result["reference"]:
        r = result["reference"]
        lines.append(f"| reference policy (`{r['name']}`, not a tree) | - | {r['mean']:.1f} ± {r['stderr']:.1f} | - | - | - |")
    lines += ["", f"Trees scored in all: {sum(c['trees_scored'] for c in result['climbs']):,}; "
                  f"{result['seconds'] / 60:.0f} minutes.", "", "The ceiling tree:", "", "```",
              to_text(parse_tree(best["tree"], vocab), vocab), "```", ""]
    out.mkdir(parents=True, exist_ok=True)
    md = out / f"ceilings_{domain}.md"
    md.write_text("\n".join(lines) + "\n")
    (out / f"ceilings_{domain}.json").write_text(json.dumps({"meta": meta, **result}, indent=2))
    return md
