"""The translation experiment: k-fold cross-validation (repeated) and leave-writers-out, per
domain and model, with exact-tree, token-wise (grid slot) and policy accuracy.

Augmentation and synthetic data are built inside each fold from its training indices only.
Each finished fold is appended to `runs.jsonl`, so an interrupted experiment resumes where it
stopped; `summarize` turns the runs into the Markdown/JSON tables and the figure.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path
from statistics import mean, pstdev
from typing import Callable, Optional, Sequence

import torch

from nl2policy.domains import get_domain
from nl2policy.language.corpus import Spec, kfold, load_corpus
from nl2policy.language.dataset import member_pairs
from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.train import fit
from nl2policy.language.translate import LOW_CONFIDENCE, tree_probability
from nl2policy.trees import GRID_SLOTS, Tree, TreeError, to_grid
from nl2policy.trees.parse import validate

PAPER_HAN2TREE = {"taxi": 86.30, "highway": 80.38}
# decoding choices a fold also scores dialled down to a smaller value (same trained networks) when
# the config sets more: record key -> (TrainedTranslator and ModelConfig attribute, that value,
# label in the summary)
DECODING_ALTERNATIVES = {"greedy_tree_acc": ("beam", 1, "greedy (beam of 1)"),
                         "no_leaf_cost_tree_acc": ("leaf_cost", 0.0, "no early-leaf cost"),
                         "no_mention_cost_tree_acc": ("mention_cost", 0.0, "no action-mention check"),
                         "first_3_members_tree_acc": ("ensemble", 3, "its first 3 members (the default's networks)"),
                         "first_4_members_tree_acc": ("ensemble", 4, "its first 4 members"),
                         "first_5_members_tree_acc": ("ensemble", 5, "its first 5 members")}


def slot_accuracy(pred: Tree, gold: Tree) -> float:
    """Token-wise accuracy on the 15-slot grid: slots filled in either tree that agree."""
    a, b = to_grid(pred), to_grid(gold)
    used = [i for i in range(GRID_SLOTS) if a[i] is not None or b[i] is not None]
    return sum(a[i] == b[i] for i in used) / len(used)


def score(domain: str, preds: Sequence[Tree], golds: Sequence[Tree]) -> dict:
    d = get_domain(domain)
    valid = 0
    for p in preds:
        try:
            validate(p, d.vocab)
            valid += 1
        except TreeError:
            pass
    n = len(golds)
    return {"n": n, "valid": valid,
            "tree_acc": sum(p == g for p, g in zip(preds, golds)) / n,
            "token_acc": sum(slot_accuracy(p, g) for p, g in zip(preds, golds)) / n,
            "policy_acc": sum(d.same_policy(p, g) for p, g in zip(preds, golds)) / n}


def run_fold(domain: str, specs: Sequence[Spec], train_idx: Sequence[int], test_idx: Sequence[int], name: str,
             seed: int, cache: MiniLMCache, workers: int = 1) -> dict:
    start = time.time()
    pairs = member_pairs(domain, specs, train_idx, MODELS[name])
    model = fit(domain, name, MODELS[name], pairs, seed, cache=cache,
                vocab_texts=[specs[i].description for i in train_idx], workers=workers)
    texts = [specs[i].description for i in test_idx]
    decoded = model.predict(texts)
    preds = [t for t, _ in decoded]
    golds = [specs[i].tree for i in test_idx]
    result = score(domain, preds, golds)
    # calibration: is "confident" (the product of node probabilities, what translate() reports
    # for an on-topic text, at or above its warning threshold) more often right than "unsure"?
    sure = [tree_probability(probs) >= LOW_CONFIDENCE for _, probs in decoded]
    right = [p == g for p, g in zip(preds, golds)]
    result.update(confident=sum(sure), confident_right=sum(s and r for s, r in zip(sure, right)),
                  unsure_right=sum(r and not s for s, r in zip(sure, right)))
    # the same networks on the same fold, decoded with less of each decoding choice the config makes
    for key, (attr, off, _) in DECODING_ALTERNATIVES.items():
        if getattr(model.cfg, attr) > off:
            setattr(model, attr, off)
            result[key] = score(domain, [t for t, _ in model.predict(texts)], golds)["tree_acc"]
            setattr(model, attr, None)  # back to the config's
    result.update(train_pairs=len(pairs(0) if callable(pairs) else pairs), seconds=round(time.time() - start, 1))
    return result


def machine() -> str:
    """The kind of CPU a fold trained on, recorded with it. A fold retrains bit for bit on the
    same kind of CPU, not across kinds: the float kernels PyTorch picks depend on the
    instruction set (AVX-512 or not), and 30 epochs turn a last-bit difference into other
    networks, a few trees apart on a 40-description fold."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor() or platform.machine()
    model = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")), "")
    flags = next((line.split(":", 1)[1].split() for line in info.splitlines() if line.startswith("flags")), [])
    return f"{model or platform.machine()}, {'avx512' if 'avx512f' in flags else 'no avx512'}"


def plan_folds(specs: Sequence[Spec], protocol: str, repeats: int) -> list[tuple[str, list[int], list[int]]]:
    """(fold key, train, test). "cv": 5 folds x `repeats` (fold seed = repeat); "writers":
    4 folds of 2 held-out writers each."""
    if protocol == "cv":
        return [(f"cv-r{r}-f{f}", tr, te) for r in range(repeats) for f, (tr, te) in enumerate(kfold(specs, 5, seed=r))]
    return [(f"writers-f{f}", tr, te) for f, (tr, te) in enumerate(kfold(specs, 4, seed=0, by_writer=True))]


def run_experiment(plan: Sequence[tuple[str, str, str, int]], out: Path,
                   progress: Optional[Callable[[str], None]] = None, workers: int = 1) -> Path:
    """`plan`: (domain, model, protocol, repeats). Appends each fold to out/runs.jsonl.
    `workers`: processes training an ensemble's members side by side (train.fit); the folds'
    results are the same as with one, only the recorded seconds change."""
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    runs = out / "runs.jsonl"
    done = {(r["domain"], r["model"], r["fold"]) for r in _read(runs)}
    caches: dict[str, MiniLMCache] = {}
    for domain, name, protocol, repeats in plan:
        specs = load_corpus(domain)
        cache = caches.setdefault(domain, MiniLMCache())
        for key, tr, te in plan_folds(specs, protocol, repeats):
            if (domain, name, key) in done:
                continue
            if progress:
                progress(f"{domain} {name} {key}")
            seed = int(key.split("-r")[1][0]) if "-r" in key else 0
            result = run_fold(domain, specs, tr, te, name, seed, cache, workers)
            result.update(domain=domain, model=name, fold=key, protocol=protocol, machine=machine())
            with runs.open("a") as fh:
                fh.write(json.dumps(result) + "\n")
            done.add((domain, name, key))  # a later plan step (e.g. cv3 after cv1) must not redo it
    return runs


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


def _read(path: Path) -> list[dict]:
    return [json.loads(l) for l in path.read_text().splitlines() if l.strip()] if path.is_file() else []


def summarize(out: Path, command: str, budget: str, planned: Sequence[tuple[str, str, str, int]] = ()) -> Path:
    """Markdown + JSON tables (mean (std) over folds) and a bar figure, from runs.jsonl."""
    from nl2policy.report import provenance

    runs = _one_per_fold(_read(out / "runs.jsonl"))
    table = _by_row(runs)
    rows = []
    for (domain, model, protocol), rs in sorted(table.items()):
        row = {"domain": domain, "model": model, "protocol": protocol, "folds": len(rs),
               "all_valid": all(r["valid"] == r["n"] for r in rs), "train_pairs": rs[0]["train_pairs"],
               "seconds_per_fold": round(mean(r["seconds"] for r in rs), 1)}
        for m in ("tree_acc", "token_acc", "policy_acc"):
            vals = [100 * r[m] for r in rs]
            row[m] = {"mean": round(mean(vals), 2), "std": round(pstdev(vals), 2)}
        rows.append(row)
    meta = provenance(command)
    (out / "translation.json").write_text(json.dumps({"meta": meta, "budget": budget, "rows": rows}, indent=2))
    lines = ["# Translation accuracy (%), mean (std) over folds", "", f"Made by: `{command}`  ", f"On: {meta['made']}  ",
             f"Budget and seeds: {budget}", "",
             "Protocols: `cv` = 5-fold cross-validation, fold seeds 0..R-1 (R repeats, see folds column); "
             "`writers` = leave-writers-out, 4 folds of 2 held-out writers (fold seed 0). "
             "Model seed = repeat index. Paper's HAN2Tree (CV): taxi 86.30, highway 80.38.", "",
             "| domain | model | protocol | folds | tree acc | token acc | policy acc | all outputs valid | train pairs | s/fold |",
             "|---|---|---|---:|---:|---:|---:|---|---:|---:|"]
    for r in rows:
        cell = lambda m: f"{r[m]['mean']:.2f} ({r[m]['std']:.2f})"
        lines.append(f"| {r['domain']} | {r['model']} | {r['protocol']} | {r['folds']} | {cell('tree_acc')} | "
                     f"{cell('token_acc')} | {cell('policy_acc')} | {'yes' if r['all_valid'] else 'NO'} | "
                     f"{r['train_pairs']} | {r['seconds_per_fold']} |")
    lines += _against_paper(rows)
    lines += _writer_breakdown(runs)
    lines += _decoding_effects(runs)
    lines += _variants(runs)
    lines += _calibration(runs)
    missing = [f"{d} {m} {p}: {want - len(table.get((d, m, p), []))} of {want} folds"
               for d, m, p, want in planned if len(table.get((d, m, p), [])) < want]
    if missing:
        lines += ["", "**Planned but not run (stopped at the time budget):** " + "; ".join(missing) + "."]
    (out / "translation.json").write_text(json.dumps({"meta": meta, "budget": budget, "rows": rows, "not_run": missing}, indent=2))
    md = out / "translation.md"
    md.write_text("\n".join(lines) + "\n")
    _figure(rows, out / "translation.png")
    return md


PAPER_FOLDS = 15
"""The paper's protocol: 5-fold cross-validation repeated 3 times."""


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
            lines.append(f"| {domain} | {model} | {part} | {len(rs)} | {label} | "
                         + _paired_cells([(100 * r["tree_acc"], 100 * r[key]) for r in rs]))
    if not lines:
        return []
    return ["", "## Decoding choices, each against the same trained networks decoded with less of it (same folds)", "",
            "| domain | model | folds | n | compared with | tree acc, as configured | tree acc, compared | folds better / worse |",
            "|---|---|---|---:|---|---:|---:|---|"] + lines


VARIANT_FIELDS = ("encoder", "decoder", "minilm", "minilm_layers", "synthetic")
"""What makes a model a variant of the default: the same networks and training data, differing only
in how many are trained and how, or in how they are decoded."""


def _variants(runs: list[dict], base: str = DEFAULT_MODEL) -> list[str]:
    """Each variant of the default (see VARIANT_FIELDS) beside the default on exactly the folds both
    ran: a variant run on repeat 0 only must not be read against the default's mean over three
    repeats, since one fold moves by several points with the training run alone."""
    same = lambda name: name in MODELS and all(getattr(MODELS[name], f) == getattr(MODELS[base], f) for f in VARIANT_FIELDS)
    ref = {(r["domain"], r["fold"]): 100 * r["tree_acc"] for r in runs if r["model"] == base}
    rows = _by_row([r for r in runs if r["model"] != base and same(r["model"]) and (r["domain"], r["fold"]) in ref])
    if not rows:
        return []
    lines = ["", f"## Variants of the default ({base}), each beside the default on the same folds", "",
             "| domain | variant | protocol | folds | variant tree acc | default tree acc | folds better / worse |",
             "|---|---|---|---:|---:|---:|---|"]
    for (domain, model, protocol), rs in sorted(rows.items()):
        lines.append(f"| {domain} | {model} | {protocol} | {len(rs)} | "
                     + _paired_cells([(100 * r["tree_acc"], ref[(r["domain"], r["fold"])]) for r in rs]))
    return lines


def _paired_cells(pairs: list[tuple[float, float]]) -> str:
    """The last three cells of a paired-comparison row: both means and folds better / worse."""
    return (f"{mean(a for a, _ in pairs):.2f} | {mean(b for _, b in pairs):.2f} | "
            f"{sum(a > b for a, b in pairs)} / {sum(a < b for a, b in pairs)} |")


def held_out_writers(domain: str) -> dict[str, str]:
    """Leave-writers-out fold key -> the writers it holds out (as `plan_folds` makes them)."""
    specs = load_corpus(domain)
    return {key: " + ".join(sorted({specs[i].writer for i in te}))
            for key, _, te in plan_folds(specs, "writers", 1)}


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


def _calibration(runs: list[dict]) -> list[str]:
    """Pooled over folds: how many translations are confident, and how often each kind is right.
    A useful confidence makes the confident ones right far more often than the unsure ones."""
    runs = [r for r in runs if "confident" in r]
    if not runs:
        return []
    lines = ["", f"Confidence (test descriptions pooled over folds; confident = node-probability product >= {LOW_CONFIDENCE}):", "",
             "| domain | model | protocol | confident share | tree acc when confident | tree acc when unsure |",
             "|---|---|---|---:|---:|---:|"]
    pct = lambda a, b: f"{100 * a / b:.1f}" if b else "-"
    for (domain, model, protocol), rs in sorted(_by_row(runs).items()):
        n, sure = sum(r["n"] for r in rs), sum(r["confident"] for r in rs)
        lines.append(f"| {domain} | {model} | {protocol} | {pct(sure, n)} | {pct(sum(r['confident_right'] for r in rs), sure)} | "
                     f"{pct(sum(r['unsure_right'] for r in rs), n - sure)} |")
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
