"""Leave-style-out: how a translator trained on synthetic pairs alone reads a whole way of
writing it never saw.

A domain nobody has described (lunar) has no held-out writers to score on. Its translator
learns from the synthetic generator (language/synthetic/) only, so the question this protocol
asks is the one that matters before real descriptions arrive: does it read *styles* it was not
trained on, or only the generator's habits? Each fold holds out a group of whole-tree styles
(``FOLDS``): the networks train on pairs drawn from the other styles only (a held-out style
appears nowhere, not even in a closing summary), and are tested on fresh pairs in the held-out
styles whose trees training never saw (no synthetic training pair has a test tree's policy).

What it cannot tell: every fold's text, held out or not, comes from one generator, with the
domain's phrases.toml wording for each question and action and the generator's shared
persona effects (speech, texting, typos). Real writers choose words the phrases never list and
structure text no style here has; NWNT on taxi and highway (where writers exist) measured
v3 15-25 points below its lab protocols. Read its numbers as an upper bound on new writers.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, Optional

from nl2policy.domains import get_domain
from nl2policy.language.corpus import policy_key
from nl2policy.language.findings import train_findings
from nl2policy.language.models.config import DEFAULT_MODEL
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.shipping import shipped_config
from nl2policy.language.synthetic import STYLES, synthetic_pairs
from nl2policy.language.train import fit
from nl2policy.language.translate import LOW_CONFIDENCE, tree_probability
from nl2policy.trees import TreeError
from nl2policy.trees.parse import validate

FOLDS: dict[str, tuple[str, ...]] = {
    "prose": ("nested", "chain"),
    "rule lists": ("rules", "default", "memo"),
    "structured": ("outline", "qa", "table", "code", "arrows"),
}
"""Held-out groups: running prose, one rule a line, and layouts that carry the tree (outlines,
questions and answers, tables, pseudo-code, arrows). Every style is in exactly one group."""
assert sorted(s for group in FOLDS.values() for s in group) == sorted(STYLES)

TEST_SEED = 90_000  # the held-out pairs' draw: apart from every training member's (seed + member)


def fold_recipe(domain: str, synthetic: int):
    """The config a fold trains: the shipped recipe with the domain's [translator] settings and
    `synthetic` pairs a network."""
    return replace(shipped_config(domain, DEFAULT_MODEL), synthetic=synthetic)


def run_fold(domain: str, fold: str, synthetic: int, test_pairs: int, seed: int = 0, workers: int = 1,
             progress: Optional[Callable[[int, int], None]] = None) -> dict:
    """Train the shipped recipe (with `synthetic` pairs a network) on every style but `fold`'s and
    score it on `test_pairs` fresh pairs in `fold`'s styles."""
    start = time.time()
    held = FOLDS[fold]
    kept = [s for s in STYLES if s not in held]
    test = [(style, text, tree) for k, style in enumerate(held)  # the same count of each held-out style
            for text, tree in synthetic_pairs(domain, test_pairs // len(held), TEST_SEED + k, styles={style})]
    test_keys = {policy_key(domain, tree) for _, _, tree in test}
    cfg = fold_recipe(domain, synthetic)
    cfg_seed = seed + cfg.seed_offset

    def pairs(member: int) -> list:
        return synthetic_pairs(domain, cfg.synthetic_for(member), cfg_seed + member, styles=kept,
                               exclude=lambda tree: policy_key(domain, tree) in test_keys)

    cache = MiniLMCache()
    model = fit(domain, DEFAULT_MODEL, cfg, pairs, seed, cache=cache, progress=progress, workers=workers)
    if cfg.findings_cost and model.findings is None:
        model.findings = train_findings(domain, pairs(0), cfg_seed, cache)
    decoded = model.predict([text for _, text, _ in test])
    vocab = get_domain(domain).vocab
    valid = sum(_valid(tree, vocab) for tree, _ in decoded)
    right = [pred == gold for (pred, _), (_, _, gold) in zip(decoded, test)]
    policy = [policy_key(domain, pred) == policy_key(domain, gold) for (pred, _), (_, _, gold) in zip(decoded, test)]
    sure = [tree_probability(probs) >= LOW_CONFIDENCE for _, probs in decoded]
    by_style = {style: 100.0 * sum(r for (s, _, _), r in zip(test, right) if s == style)
                / sum(s == style for s, _, _ in test) for style in held}
    return {"domain": domain, "fold": fold, "held_out": list(held), "trained_on": kept, "model": DEFAULT_MODEL,
            "recipe": cfg.to_dict(), "synthetic_per_network": synthetic, "ensemble": cfg.ensemble, "seed": seed, "test_pairs": len(test),
            "exact": 100.0 * sum(right) / len(test), "policy": 100.0 * sum(policy) / len(test),
            "valid": 100.0 * valid / len(test), "confident": sum(sure),
            "confident_right": sum(s and r for s, r in zip(sure, right)),
            "exact_by_style": by_style, "seconds": round(time.time() - start, 1)}


def _valid(tree, vocab) -> bool:
    try:
        validate(tree, vocab)
        return True
    except TreeError:
        return False


def _settings(row: dict) -> str:
    """The training and decoding settings a fold recorded (older rows did not record them)."""
    recipe = row.get("recipe")
    if recipe is None:
        return " (other settings not recorded)"
    return f", {recipe['epochs']} epochs, the learned findings weighing the beam {recipe['findings_cost']:g}"


def resumable(row: dict, recipe: dict, seed: int, test_pairs: int) -> bool:
    """Whether a kept fold was run with the settings asked for now, so a resumed table holds one
    recipe: the same model and recipe (the domain's [translator] settings included), seed and test size."""
    size = test_pairs // len(FOLDS[row["fold"]]) * len(FOLDS[row["fold"]])
    return (row["model"] == DEFAULT_MODEL and row.get("recipe") == recipe and row["seed"] == seed
            and row["test_pairs"] == size)


def write_table(rows: list[dict], out: Path, command: str) -> Path:
    """results table: one line a fold, and the mean."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "runs.json").write_text(json.dumps(rows, indent=2))
    lines = [f"# Leave-style-out: the {rows[0]['domain']} translator on whole styles it never saw", "",
             f"Command: `{command}`", "",
             f"Recipe: {rows[0]['model']}, {rows[0]['ensemble']} networks, {rows[0]['synthetic_per_network']} "
             f"synthetic pairs a network from the styles not held out{_settings(rows[0])}, seed {rows[0]['seed']}; test: "
             f"{rows[0]['test_pairs']} fresh pairs a fold in the held-out styles, seed {TEST_SEED}, trees no "
             "training pair has. What this protocol cannot tell: experiments/translation/leave_style_out.py.", "",
             "| held out | styles | exact % | policy % | valid % | confident (right) | by style (exact %) | minutes |",
             "|---|---|---:|---:|---:|---:|---|---:|"]
    for r in rows:
        styles = ", ".join(f"{s} {v:.0f}" for s, v in r["exact_by_style"].items())
        lines.append(f"| {r['fold']} | {', '.join(r['held_out'])} | {r['exact']:.1f} | {r['policy']:.1f} | "
                     f"{r['valid']:.0f} | {r['confident']} ({r['confident_right']}) | {styles} | {r['seconds'] / 60:.0f} |")
    mean = lambda key: sum(r[key] for r in rows) / len(rows)  # noqa: E731
    lines.append(f"| **mean** | | **{mean('exact'):.1f}** | {mean('policy'):.1f} | {mean('valid'):.0f} | | | |")
    path = out / "leave_style_out.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def main(domain: str = "lunar", synthetic: int = 1000, test_pairs: int = 240, seed: int = 0,
         out: Path = Path("results/translation/leave_style_out"), workers: int = 1,
         fold: Optional[list[str]] = None) -> None:
    """Leave-style-out folds of the shipped recipe (resumable: a fold already in OUT/runs.json is kept)."""
    import torch

    from nl2policy.console import console, domain_or_fail, err, progress_bar

    torch.set_num_threads(1)
    domain_or_fail(domain)
    unknown = set(fold or ()) - set(FOLDS)
    if unknown:
        err.print(f"[red]error:[/red] unknown fold(s) {sorted(unknown)}; known: {', '.join(FOLDS)}")
        raise SystemExit(2)
    command = (f"python -m experiments.translation.leave_style_out --domain {domain} --synthetic {synthetic} "
               f"--test-pairs {test_pairs} --seed {seed} --workers {workers} --out {out}")
    runs_path = out / domain / "runs.json"
    kept_rows = json.loads(runs_path.read_text()) if runs_path.is_file() else []
    recipe = json.loads(json.dumps(fold_recipe(domain, synthetic).to_dict()))  # as runs.json holds it
    others = [r["fold"] for r in kept_rows if not resumable(r, recipe, seed, test_pairs)]
    if others:  # resuming would rewrite (and lose) them, or mix recipes in one table
        err.print(f"[red]error:[/red] {runs_path} holds folds ({', '.join(others)}) of another translator or other "
                  f"settings than {DEFAULT_MODEL}'s now with these options; write to another --out")
        raise SystemExit(2)
    rows = kept_rows
    for name in fold or list(FOLDS):
        if any(r["fold"] == name for r in rows):
            continue
        with progress_bar() as bar:
            task = bar.add_task(f"{domain}: trained without {name}", total=None)
            rows.append(run_fold(domain, name, synthetic, test_pairs, seed, workers,
                                 progress=lambda done, total: bar.update(task, completed=done, total=total)))
        write_table(rows, out / domain, command)
    if not (out / domain / "leave_style_out.md").is_file():  # every fold kept, its table gone
        write_table(rows, out / domain, command)
    console.print((out / domain / "leave_style_out.md").read_text(), markup=False, highlight=False)


if __name__ == "__main__":
    import typer

    typer.run(main)
