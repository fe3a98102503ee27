"""The translation experiment's report: from the folds in `runs.jsonl` (written by
`evaluate.run_experiment`), the Markdown and JSON tables and the bar figure under results/.

Every table reads the folds as recorded; a fold recorded twice counts once, and comparisons fold
by fold pair only folds that one kind of CPU trained (a fold retrains bit for bit on its own kind).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from statistics import mean, pstdev
from typing import Sequence

from nl2policy.language.corpus import load_corpus
from experiments.translation.evaluate import DECODING_ALTERNATIVES, held_out_writers, plan_folds, read_runs, unseen_trees
from nl2policy.language.models.config import DEFAULT_MODEL, DEFAULT_NETWORKS, MODELS
from experiments.translation.reproduction import (decoded_as, fold_machine, machine_kinds, machine_labels, reproduction_checks,
                                              reproduction_lines)
from nl2policy.language.translate import LOW_CONFIDENCE

PAPER_HAN2TREE = {"taxi": 86.30, "highway": 80.38}


def _one_per_fold(runs: list[dict]) -> list[dict]:
    """The first record of each (domain, model, fold): a fold recorded twice (two processes on
    one plan) must not count twice in a mean."""
    first: dict[tuple, dict] = {}
    for r in runs:
        first.setdefault((r["domain"], r["model"], r["fold"]), r)
    return list(first.values())


def _by_row(runs: list[dict]) -> dict[tuple[str, str, str], list[dict]]:
    """Folds grouped by table row: (domain, model, protocol)."""
    rows: dict[tuple[str, str, str], list[dict]] = {}
    for r in runs:
        rows.setdefault((r["domain"], r["model"], r["protocol"]), []).append(r)
    return rows


def summarize(out: Path, command: str, budget: str, planned: Sequence[tuple[str, str, str, int]] = ()) -> Path:
    """Markdown + JSON tables (mean (std) over folds) and a bar figure, from runs.jsonl."""
    from nl2policy.report import provenance

    runs = _one_per_fold(read_runs(out / "runs.jsonl"))
    table = _by_row(runs)
    labels = machine_labels(runs)
    checks = reproduction_checks(runs)
    kinds = machine_kinds(checks, labels)
    rows = []
    for (domain, model, protocol), rs in sorted(table.items()):
        row = {"domain": domain, "model": model, "protocol": protocol, "folds": len(rs),
               "all_valid": all(r["valid"] == r["n"] for r in rs), "train_pairs": rs[0]["train_pairs"],
               "seconds_per_fold": round(mean(r["seconds"] for r in rs), 1),
               "reused": all("networks_from" in r for r in rs),
               "machines": {m: n for m in labels if (n := sum(fold_machine(r) == m for r in rs))}}
        for m in ("tree_acc", "token_acc", "policy_acc"):
            vals = [100 * r[m] for r in rs]
            row[m] = {"mean": round(mean(vals), 2), "std": round(pstdev(vals), 2)}
        rows.append(row)
    meta = provenance(command)
    lines = ["# Translation accuracy (%), mean (std) over folds", "", f"Made by: `{command}`  ", f"On: {meta['made']}  ",
             f"Budget and seeds: {budget}", "",
             "Protocols: `cv` = 5-fold cross-validation, fold seeds 0..R-1 (R repeats, see folds column); "
             "`writers` = leave-writers-out, 4 folds of 2 held-out writers (fold seed 0). "
             "Model seed = repeat index. Paper's HAN2Tree (CV): taxi 86.30, highway 80.38.", "",
             "Machines (folds retrain bit for bit only on the kind of CPU that first ran them; seconds per fold "
             "depend on it and on the worker processes): " + "; ".join(f"{label} = {m}" for m, label in labels.items()) + ".",
             *reproduction_lines(checks, kinds, labels), "",
             *(["\\* decoded the networks another model trained on the same folds (python -m experiments.translation "
                "--networks-from, evaluate.kept_networks): seconds of decoding only.", ""]
               if any(r["reused"] for r in rows) else []),
             "| domain | model | protocol | folds | tree acc | token acc | policy acc | all outputs valid | train pairs | s/fold | machine |",
             "|---|---|---|---:|---:|---:|---:|---|---:|---:|---|"]
    for r in rows:
        cell = lambda m: f"{r[m]['mean']:.2f} ({r[m]['std']:.2f})"
        lines.append(f"| {r['domain']} | {r['model']} | {r['protocol']} | {r['folds']} | {cell('tree_acc')} | "
                     f"{cell('token_acc')} | {cell('policy_acc')} | {'yes' if r['all_valid'] else 'NO'} | "
                     f"{r['train_pairs']} | {r['seconds_per_fold']}{' *' if r['reused'] else ''} | "
                     f"{_machine_cell(r['machines'], labels)} |")
    lines += _against_paper(rows)
    lines += _writer_breakdown(runs)
    lines += _decoding_effects(runs)
    lines += _variants(runs, kinds)
    lines += _calibration(runs)
    lines += _unseen(runs, sorted({r["domain"] for r in rows}))
    missing = [f"{d} {m} {p}: {want - len(table.get((d, m, p), []))} of {want} folds"
               for d, m, p, want in planned if len(table.get((d, m, p), [])) < want]
    if missing:
        lines += ["", "**Planned but not run (stopped at the time budget):** " + "; ".join(missing) + "."]
    (out / "translation.json").write_text(json.dumps({"meta": meta, "budget": budget, "rows": rows, "not_run": missing,
                                                           "reproduction": [{"machines": list(p), "agree": a, "folds": n}
                                                                            for p, (a, n) in sorted(checks.items())]}, indent=2))
    md = out / "translation.md"
    md.write_text("\n".join(lines) + "\n")
    _figure(rows, out / "translation.png")
    return md


def _machine_cell(counts: dict[str, int], labels: dict[str, str]) -> str:
    """"A" when one machine ran every fold of a row, else "A 13, B 2"."""
    if len(counts) == 1:
        return labels[next(iter(counts))]
    return ", ".join(f"{labels[m]} {n}" for m, n in counts.items())


PAPER_FOLDS = 15
"""The paper's protocol: 5-fold cross-validation repeated 3 times."""
CV_REPEATS = PAPER_FOLDS // 5


def _against_paper(rows: list[dict]) -> list[str]:
    """Per domain, the model with the best cross-validated tree accuracy over the paper's protocol
    (rows with fewer folds are left out: one repeat moves by points with the training run alone),
    its leave-writers-out accuracy where it ran, and the paper's HAN2Tree beside it."""
    lines = []
    for domain in sorted({r["domain"] for r in rows}):
        full = [r for r in rows if r["domain"] == domain and r["protocol"] == "cv" and r["folds"] >= PAPER_FOLDS]
        if not full or domain not in PAPER_HAN2TREE:
            continue
        best = max(full, key=lambda r: r["tree_acc"]["mean"])
        writers = [r for r in rows if r["domain"] == domain and r["model"] == best["model"] and r["protocol"] == "writers"]
        held = (f"{writers[0]['tree_acc']['mean']:.2f} ({writers[0]['folds']} of 4 folds)" if writers else "not run")
        paper = PAPER_HAN2TREE[domain]
        lines.append(f"| {domain} | {best['model']} | {best['tree_acc']['mean']:.2f} ({best['tree_acc']['std']:.2f}) | "
                     f"{held} | {paper:.2f} | {'yes' if best['tree_acc']['mean'] >= paper else 'no'} |")
    if not lines:
        return []
    return ["", f"## Best model against the paper (cross-validated over at least {PAPER_FOLDS} folds, as the paper)", "",
            "| domain | best model | CV tree acc | leave-writers-out tree acc | paper's HAN2Tree (CV) | at or above the paper |",
            "|---|---|---:|---:|---:|---|"] + lines


def _decoding_effects(runs: list[dict]) -> list[str]:
    """Models decoded with a beam, an early-leaf cost or more than 3 members also record the same
    networks on the same folds decoded with less of it: each choice's own effect, side by side.
    CV repeat 0 gets its own line because the experimental leaf cost was chosen on an exploratory
    run of those folds."""
    lines = []
    for key, (_, _, label) in DECODING_ALTERNATIVES.items():
        groups: dict[tuple[str, str, str], list[dict]] = {}
        for r in runs:
            if key in r:
                part = r["protocol"] if r["protocol"] != "cv" else ("cv, repeat 0" if "-r0-" in r["fold"] else "cv, repeats 1+")
                groups.setdefault((r["domain"], r["model"], part), []).append(r)
        for (domain, model, part), rs in sorted(groups.items()):
            same = decoded_as(model, key)
            lines.append(f"| {domain} | {model} | {part} | {len(rs)} | {label}{' (= ' + ', '.join(same) + ')' if same else ''} | "
                         + _paired_cells([(100 * r["tree_acc"], 100 * r[key]) for r in rs]))
    if not lines:
        return []
    return ["", "## Decoding choices, each against the same trained networks decoded with less of it (same folds)", "",
            "| domain | model | folds | n | compared with | tree acc, as configured | tree acc, compared | folds better / worse |",
            "|---|---|---|---:|---|---:|---:|---|"] + lines


VARIANT_FIELDS = ("encoder", "decoder", "minilm", "minilm_layers")
"""What makes a model a variant of the default: the same kind of network, also trained on synthetic
pairs (see `is_variant`), differing in how many are trained, on how much of which data, how wide,
or how they are decoded."""


def is_variant(name: str, base: str = DEFAULT_NETWORKS) -> bool:
    """Whether `name` is a variant of `base` (VARIANT_FIELDS equal, and both trained with synthetic
    pairs or both without: the models without them are the ablation, set beside one another in the
    main table)."""
    if name not in MODELS or name == base:
        return False
    cfg, ref = MODELS[name], MODELS[base]
    return all(getattr(cfg, f) == getattr(ref, f) for f in VARIANT_FIELDS) and bool(cfg.synthetic) == bool(ref.synthetic)


def _variants(runs: list[dict], kinds: dict[str, str], base: str = DEFAULT_NETWORKS) -> list[str]:
    """Each variant of the default's networks (`base`, DEFAULT_NETWORKS; see is_variant) beside
    them on exactly the folds both ran on the same kind of machine (`kinds`: machine_kinds): a
    variant run on repeat 0 only must not be read against the default's mean over three repeats,
    since one fold moves by several points with the training run alone, and a fold retrained on
    another kind of CPU is another training run."""
    key = lambda r: (r["domain"], r["fold"], kinds.get(fold_machine(r), fold_machine(r)))
    ref = {key(r): 100 * r["tree_acc"] for r in runs if r["model"] == base}
    rows = _by_row([r for r in runs if is_variant(r["model"], base) and key(r) in ref])
    if not rows:
        return []
    title = (f"the default ({base})" if base == DEFAULT_MODEL else
             f"the default's networks ({base}; the default, {DEFAULT_MODEL}, decodes them with more checks)")
    lines = ["", f"## Variants of {title}, each beside them on the same folds", "",
             "| domain | variant | protocol | folds | variant tree acc | default tree acc | folds better / worse |",
             "|---|---|---|---:|---:|---:|---|"]
    for (domain, model, protocol), rs in sorted(rows.items()):
        lines.append(f"| {domain} | {model} | {protocol} | {len(rs)} | "
                     + _paired_cells([(100 * r["tree_acc"], ref[key(r)]) for r in rs]))
    reruns = sorted({m for _, m, _ in rows if is_rerun(m, base)})
    if reruns:
        lines += ["", f"{', '.join(reruns)}: the default's own recipe trained again with other seeds (initial weights and "
                  "draws of augmented and synthetic pairs), not a change to it. "
                  + ("Its distance" if len(reruns) == 1 else "Their distance") + " from the default is what "
                  "another training run alone moves, the yardstick for the other rows."]
    return lines


def is_rerun(name: str, base: str = DEFAULT_NETWORKS) -> bool:
    """Whether `name` is `base` with other seeds only (ModelConfig.seed_offset)."""
    cfg, ref = MODELS.get(name), MODELS[base]
    return cfg is not None and cfg.seed_offset != ref.seed_offset and replace(cfg, seed_offset=ref.seed_offset) == ref


def _paired_cells(pairs: list[tuple[float, float]]) -> str:
    """The last three cells of a paired-comparison row: both means and folds better / worse."""
    return (f"{mean(a for a, _ in pairs):.2f} | {mean(b for _, b in pairs):.2f} | "
            f"{sum(a > b for a, b in pairs)} / {sum(a < b for a, b in pairs)} |")


def _writer_breakdown(runs: list[dict]) -> list[str]:
    """Tree accuracy per held-out writer pair: which writing styles a model fails to read."""
    runs = [r for r in runs if r["protocol"] == "writers"]
    if not runs:
        return []
    lines = ["", "Leave-writers-out tree accuracy (%) per held-out writer pair:", ""]
    for domain in sorted({r["domain"] for r in runs}):
        names = held_out_writers(domain)
        keys = sorted(names)
        lines += [f"| {domain} | " + " | ".join(names[k] for k in keys) + " |", "|---" * (len(keys) + 1) + "|"]
        for model in sorted({r["model"] for r in runs if r["domain"] == domain}):
            acc = {r["fold"]: 100 * r["tree_acc"] for r in runs if r["domain"] == domain and r["model"] == model}
            lines.append(f"| {model} | " + " | ".join(f"{acc[k]:.0f}" if k in acc else "not run" for k in keys) + " |")
        lines.append("")
    return lines


def _pct(part: int, whole: int) -> str:
    """A share of a pooled count, in percent, or "-" when there is nothing to share."""
    return f"{100 * part / whole:.1f}" if whole else "-"


def _calibration(runs: list[dict]) -> list[str]:
    """Pooled over folds: how many translations are confident, and how often each kind is right.
    A useful confidence makes the confident ones right far more often than the unsure ones."""
    runs = [r for r in runs if "confident" in r]
    if not runs:
        return []
    lines = ["", f"Confidence (test descriptions pooled over folds; confident = node-probability product >= {LOW_CONFIDENCE}):", "",
             "| domain | model | protocol | confident share | tree acc when confident | tree acc when unsure |",
             "|---|---|---|---:|---:|---:|"]
    for (domain, model, protocol), rs in sorted(_by_row(runs).items()):
        n, sure = sum(r["n"] for r in rs), sum(r["confident"] for r in rs)
        lines.append(f"| {domain} | {model} | {protocol} | {_pct(sure, n)} | {_pct(sum(r['confident_right'] for r in rs), sure)} | "
                     f"{_pct(sum(r['unsure_right'] for r in rs), n - sure)} |")
    return lines


def _unseen(runs: list[dict], domains: list[str]) -> list[str]:
    """How many test descriptions have a tree that no training description has (from the folds
    alone, no model), and, for the folds that record it, each model's accuracy on those and on
    the rest. Whether a model can compose a tree it never saw decides most of what it misses."""
    lines = ["", "## Trees no training description has", "",
             f"Test descriptions whose tree no description of their training fold has (the folds of {CV_REPEATS} CV "
             "repeats, and of leave-writers-out):", "", "| domain | protocol | test descriptions | tree unseen in training | share (%) |",
             "|---|---|---:|---:|---:|"]
    for domain in domains:
        specs = load_corpus(domain)
        for protocol, repeats in (("cv", CV_REPEATS), ("writers", 1)):
            flags = [u for _, tr, te in plan_folds(specs, protocol, repeats) for u in unseen_trees(specs, tr, te)]
            lines.append(f"| {domain} | {protocol} | {len(flags)} | {sum(flags)} | {_pct(sum(flags), len(flags))} |")
    recorded = [r for r in runs if "unseen" in r]
    if recorded:
        lines += ["", "Tree accuracy (%) on those and on the rest, test descriptions pooled over the folds that record it:", "",
                  "| domain | model | protocol | folds | unseen trees | acc on unseen | acc on seen |", "|---|---|---|---:|---:|---:|---:|"]
        for (domain, model, protocol), rs in sorted(_by_row(recorded).items()):
            n, unseen = sum(r["n"] for r in rs), sum(r["unseen"] for r in rs)
            right, unseen_right = round(sum(r["tree_acc"] * r["n"] for r in rs)), sum(r["unseen_right"] for r in rs)
            lines.append(f"| {domain} | {model} | {protocol} | {len(rs)} | {unseen} | {_pct(unseen_right, unseen)} | "
                         f"{_pct(right - unseen_right, n - unseen)} |")
    return lines


def _figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    domains = sorted({r["domain"] for r in rows})
    fig, axes = plt.subplots(1, len(domains), figsize=(6 * len(domains), 4), squeeze=False)
    for ax, domain in zip(axes[0], domains):
        rs = [r for r in rows if r["domain"] == domain]
        labels = [f"{r['model']}\n{r['protocol']}" for r in rs]
        ax.bar(range(len(rs)), [r["tree_acc"]["mean"] for r in rs], yerr=[r["tree_acc"]["std"] for r in rs],
               color=["tab:blue" if r["protocol"] == "cv" else "tab:orange" for r in rs])
        if domain in PAPER_HAN2TREE:
            ax.axhline(PAPER_HAN2TREE[domain], color="k", ls="--", lw=1, label="paper HAN2Tree (CV)")
            ax.legend(loc="lower right", fontsize=8)
        ax.set_xticks(range(len(rs)), labels, rotation=60, ha="right", fontsize=7)
        ax.set_ylabel("exact tree accuracy (%)")
        ax.set_ylim(0, 100)
        ax.set_title(f"{domain}: blue = CV, orange = leave-writers-out")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
