"""The translation experiment's report: Table 1, one table per domain, from the folds that
`evaluate.run_experiment` appends to runs.jsonl files.

A row is a model; a column is a protocol, so every model's leave-writers-out and leave-trees-out
accuracy sits beside its cross-validation. Below it: token accuracy, the decoding choices each
measured against the same networks decoded without them, and the confidence's reliability. A fold
recorded twice counts once. The long history of variants that lost stays in
results/translation/history/history.md, made by the code of its day.

    .venv/bin/python -m experiments.translation.summary --runs results/translation/history/v2/runs.jsonl \
        --runs results/translation/history/runs.jsonl --out results/translation/table1.md
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from statistics import mean, pstdev
from typing import Iterable, Optional, Sequence

from experiments.translation.evaluate import DECODING_ALTERNATIVES, read_runs
from nl2policy.language.clarify import ASK_BELOW
from nl2policy.language.models.config import DEFAULT_MODEL
from nl2policy.language.translate import LOW_CONFIDENCE

PAPER_HAN2TREE = {"taxi": 86.30, "highway": 80.38}
"""Exact tree accuracy of the paper's HAN2Tree, 5-fold CV x 3 (Tambwekar et al., RA-L 2023, Table 1)."""
PAPER_MODELS = ("seq2seq", "seq2tree", "seq2tree-minilm", "han2tree")
"""The paper's four translators (MiniLM standing in for BERT), trained on round 1 as in the paper."""

PROTOCOLS = {
    "cv": "CV (round 1)",
    "writers": "leave-writers-out (round 1)",
    "cvboth": "CV, round 2 in training",
    "writersboth": "leave-writers-out, round 2 in training",
    "trees": "leave-trees-out (both rounds)",
    "new": "new writers, new trees",
}
"""Table 1's columns, in order (evaluate.plan_folds defines each protocol)."""

BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0001)
"""The reliability table's bins of confidence."""


def one_per_fold(runs: Iterable[dict]) -> list[dict]:
    """The first record of each (domain, model, fold): a fold recorded twice (two processes on one
    plan, or one file read twice) must not count twice in a mean."""
    first: dict[tuple, dict] = {}
    for r in runs:
        first.setdefault((r["domain"], r["model"], r["fold"]), r)
    return list(first.values())


def rows(runs: Sequence[dict]) -> list[dict]:
    """One row per (domain, model, protocol): its folds, tree/token/policy accuracy mean (std) over
    them in percent, and whether every output was a valid tree."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for r in runs:
        groups.setdefault((r["domain"], r["model"], r["protocol"]), []).append(r)
    out = []
    for (domain, model, protocol), rs in sorted(groups.items()):
        row = {"domain": domain, "model": model, "protocol": protocol, "folds": len(rs), "n": sum(r["n"] for r in rs),
               "all_valid": all(r["valid"] == r["n"] for r in rs)}
        for m in ("tree_acc", "token_acc", "policy_acc"):
            vals = [100 * r[m] for r in rs]
            row[m] = {"mean": round(mean(vals), 2), "std": round(pstdev(vals), 2)}
        out.append(row)
    return out


def table_models(table: Sequence[dict]) -> list[str]:
    """Table 1's models: the paper's four, then the default, then any other model the runs hold."""
    models = {r["model"] for r in table}
    first = [m for m in (*PAPER_MODELS, DEFAULT_MODEL) if m in models]
    return first + sorted(models - set(first))


def table_one(table: Sequence[dict], domain: str, metric: str = "tree_acc") -> list[str]:
    """One domain's table: a row per model, a column per protocol, mean (std) [folds]."""
    mine = [r for r in table if r["domain"] == domain]
    protocols = [p for p in PROTOCOLS if any(r["protocol"] == p for r in mine)]
    cell = {(r["model"], r["protocol"]): r for r in mine}
    lines = ["| model | " + " | ".join(PROTOCOLS[p] for p in protocols) + " |", "|---" + "|---:" * len(protocols) + "|"]
    for model in table_models(mine):
        cells = []
        for p in protocols:
            r = cell.get((model, p))
            cells.append("-" if r is None else f"{r[metric]['mean']:.2f} ({r[metric]['std']:.2f}) [{r['folds']}]")
        lines.append(f"| {model} | " + " | ".join(cells) + " |")
    return lines


def decoding_effects(runs: Sequence[dict]) -> list[str]:
    """Each decoding choice a fold recorded (evaluate.DECODING_ALTERNATIVES: a beam, the learned
    findings) against the same networks decoded without it, on the same folds."""
    lines = []
    groups: dict[tuple[str, str, str, str], list[dict]] = {}
    for r in runs:
        for key in DECODING_ALTERNATIVES:
            if key in r:
                groups.setdefault((r["domain"], r["model"], r["protocol"], key), []).append(r)
    for (domain, model, protocol, key), rs in sorted(groups.items()):
        pairs = [(100 * r["tree_acc"], 100 * r[key]) for r in rs]
        lines.append(f"| {domain} | {model} | {protocol} | {len(rs)} | {DECODING_ALTERNATIVES[key][2]} | "
                     f"{mean(a for a, _ in pairs):.2f} | {mean(b for _, b in pairs):.2f} | "
                     f"{sum(a > b for a, b in pairs)} / {sum(a < b for a, b in pairs)} |")
    if not lines:
        return []
    return ["| domain | model | protocol | folds | compared with | tree acc, as configured | tree acc, compared | "
            "folds better / worse |", "|---|---|---|---:|---|---:|---:|---|"] + lines


def reliability(runs: Sequence[dict]) -> list[str]:
    """Per (domain, model, protocol) whose folds record each translation's confidence: exact
    accuracy (and count) in each bin of confidence, the accuracy of the translations at or above
    the app's low-confidence threshold, and the share below it, which the app flags."""
    groups: dict[tuple[str, str, str], list[tuple[float, bool]]] = {}
    for r in runs:
        if "confidence" in r:
            groups.setdefault((r["domain"], r["model"], r["protocol"]), []).extend((c, bool(ok)) for _, c, ok in r["confidence"])
    if not groups:
        return []
    heads = [f"{lo:.1f}-{min(hi, 1.0):.1f}" for lo, hi in zip(BINS, BINS[1:])]
    lines = ["| domain | model | protocol | " + " | ".join(heads) + f" | acc at >= {LOW_CONFIDENCE} | flagged |"
             f" acc at >= {ASK_BELOW} | share at >= {ASK_BELOW} |",
             "|---|---|---" + "|---:" * (len(heads) + 4) + "|"]
    for (domain, model, protocol), items in sorted(groups.items()):
        cells = []
        for lo, hi in zip(BINS, BINS[1:]):
            inside = [ok for c, ok in items if lo <= c < hi]
            cells.append(f"{100 * sum(inside) / len(inside):.0f} ({len(inside)})" if inside else "- (0)")
        sure = [ok for c, ok in items if c >= LOW_CONFIDENCE]
        flagged = 100 * (len(items) - len(sure)) / len(items)
        high = [ok for c, ok in items if c >= ASK_BELOW]
        lines.append(f"| {domain} | {model} | {protocol} | " + " | ".join(cells) + " | "
                     + (f"{100 * sum(sure) / len(sure):.1f}" if sure else "-") + f" | {flagged:.1f}% | "
                     + (f"{100 * sum(high) / len(high):.1f}" if high else "-") + f" | {100 * len(high) / len(items):.1f}% |")
    return lines


SIZE_BINS = (("1", 1, 1), ("2", 2, 2), ("3", 3, 3), ("4", 4, 4), ("5+", 5, 7), ("4+", 4, 7))
"""The columns of the table by tree size: questions in the gold tree (4+ = the issue's gate)."""


def by_tree_size(runs: Sequence[dict], protocol: str = "new") -> list[str]:
    """Exact accuracy (%) by the number of questions in the gold tree, per (domain, model), over
    the folds of `protocol` that record each translation (their `confidence` rows)."""
    from nl2policy.domains import get_domain
    from nl2policy.language.corpus import load_corpus
    from nl2policy.trees import to_tokens

    groups: dict[tuple[str, str], list[tuple[str, bool]]] = {}
    for r in runs:
        if r["protocol"] == protocol and "confidence" in r:
            groups.setdefault((r["domain"], r["model"]), []).extend((key, bool(ok)) for key, _, ok in r["confidence"])
    if not groups:
        return []
    sizes = {}
    for domain in {d for d, _ in groups}:
        questions = get_domain(domain).vocab.questions
        for spec in load_corpus(domain, rounds=(1, 2)):
            sizes[(domain, spec.id)] = sum(1 for t in to_tokens(spec.tree) if t in questions)
    lines = ["| domain | model | " + " | ".join(f"{name} questions" for name, _, _ in SIZE_BINS) + " |",
             "|---|---" + "|---:" * len(SIZE_BINS) + "|"]
    for (domain, model), items in sorted(groups.items()):
        cells = []
        for _, lo, hi in SIZE_BINS:
            inside = [ok for key, ok in items if lo <= sizes[(domain, key)] <= hi]
            cells.append(f"{100 * sum(inside) / len(inside):.1f} ({len(inside)})" if inside else "-")
        lines.append(f"| {domain} | {model} | " + " | ".join(cells) + " |")
    return lines


def _mean_cell(r: Optional[dict]) -> str:
    return "not run" if r is None else f"{r['tree_acc']['mean']:.2f} [{r['folds']} folds]"


def against_paper(table: Sequence[dict]) -> list[str]:
    """The default's CV on round 1 (alone, or with round 2 joining training) beside the paper's
    HAN2Tree, with its leave-writers-out beside it."""
    cell = {(r["domain"], r["model"], r["protocol"]): r for r in table}
    lines = []
    for domain, paper in PAPER_HAN2TREE.items():
        if not any(r["domain"] == domain and r["model"] == DEFAULT_MODEL for r in table):
            continue
        pairs = [(cv, writers) for cv, writers in (("cv", "writers"), ("cvboth", "writersboth"))
                 if (domain, DEFAULT_MODEL, cv) in cell] or [("cv", "writers")]  # no CV yet: the gap stays in view
        for cv, writers in pairs:
            r, w = cell.get((domain, DEFAULT_MODEL, cv)), cell.get((domain, DEFAULT_MODEL, writers))
            above = "-" if r is None else "yes" if r["tree_acc"]["mean"] >= paper else "no"
            lines.append(f"| {domain} | {PROTOCOLS[cv]} | {_mean_cell(r)} | {_mean_cell(w)} | {paper:.2f} | {above} |")
    if not lines:
        return []
    return [f"| domain | {DEFAULT_MODEL} on | CV exact | leave-writers-out exact | paper's HAN2Tree (CV) | at or above |",
            "|---|---|---:|---:|---:|---|"] + lines


def summarize(runs_files: Sequence[Path], md: Path, command: str, budget: str,
              planned: Sequence[tuple[str, str, str, int]] = (), models: Optional[dict[str, str]] = None) -> Path:
    """Table 1 (exact accuracy per protocol, and on new trees by their size) as Markdown at `md`, JSON
    beside it, and the tables a closer reader wants in MD-details.md beside it, from the folds
    in `runs_files`; `planned`: (domain, model, protocol, folds) a plan asked for, to list what
    has not run yet; `models`: the recorded models to show, each under the name to show it by
    (a recipe recorded under an older name), None: all of them."""
    from nl2policy.report import provenance

    runs = [r for path in runs_files for r in read_runs(path) if models is None or r["model"] in models]
    runs = one_per_fold(dict(r, model=models[r["model"]]) if models else r for r in runs)
    table = rows(runs)
    meta = provenance(command)
    lines = ["# Translation accuracy (%): Table 1", "", f"Made by: `{command}`  ", f"On: {meta['made']}  ",
             f"Budget and seeds: {budget}", "",
             "Each cell: mean (std) over folds [folds]. Protocols (experiments/translation/evaluate.py, plan_folds): "
             "CV = 5-fold cross-validation, repeat r with fold seed r; leave-writers-out = 4 folds of 2 held-out writers; "
             "\"round 2 in training\" = the same round-1 test folds with every round-2 spec added to training; "
             "leave-trees-out = 5 folds of held-out policies over both rounds; new writers, new trees = each round-2 "
             "writer held out with every policy they describe. Paper's HAN2Tree (CV, 5x3): taxi 86.30, highway 80.38 "
             "(Tambwekar et al., RA-L 2023).", ""]
    domains = sorted({r["domain"] for r in table})
    for domain in domains:
        lines += [f"## {domain}: exact tree accuracy", "", *table_one(table, domain), ""]
    paper = against_paper(table)
    if paper:
        lines += ["## The default against the paper", "", *paper, ""]
    invalid = [f"{r['domain']} {r['model']} {r['protocol']}" for r in table if not r["all_valid"]]
    lines += [f"Every output is a valid tree: {'yes' if not invalid else 'NO: ' + '; '.join(invalid)} "
              f"({sum(r['n'] for r in table)} translations).", ""]
    sized = by_tree_size(runs)
    if sized:
        lines += ["## New writers, new trees: exact accuracy (%) by the number of questions in the tree", "",
                  "(translations in brackets)", "", *sized, ""]
    details_path = md.with_name(md.stem + "-details.md")
    details = [f"# Translation accuracy (%): the details of Table 1 (`{md.name}`)", "", f"Made by: `{command}`  ",
               f"On: {meta['made']}", ""]
    for domain in domains:
        details += [f"## {domain}: token accuracy (15-slot grid)", "", *table_one(table, domain, "token_acc"), ""]
    effects = decoding_effects(runs)
    if effects:
        details += ["## Decoding choices against the same networks decoded without them", "", *effects, ""]
    reliable = reliability(runs)
    if reliable:
        details += ["## Confidence: exact accuracy (%) and translations per bin of confidence", "",
                    "Confidence = the product of the tree's node probabilities (what `translate` reports for an on-topic "
                    f"text); the app flags a translation below {LOW_CONFIDENCE}, and the translator asks the user about a situation "
                    f"below {ASK_BELOW} (language/clarify.py).", "", *reliable, ""]
    lines += [f"Token accuracy, each decoding choice against the same networks without it, and the confidence's "
              f"reliability: [{details_path.name}]({details_path.name}).", ""]
    have = {(r["domain"], r["model"], r["protocol"]): r["folds"] for r in table}
    missing = [f"{d} {m} {p}: {want - have.get((d, m, p), 0)} of {want} folds to go"
               for d, m, p, want in planned if have.get((d, m, p), 0) < want]
    if missing:
        lines += ["**Planned but not run yet:** " + "; ".join(missing) + ".", ""]
    md.parent.mkdir(parents=True, exist_ok=True)
    md.write_text("\n".join(lines))
    details_path.write_text("\n".join(details))
    md.with_suffix(".json").write_text(json.dumps({"meta": meta, "budget": budget, "rows": table, "not_run": missing},
                                                  indent=2))
    return md


def main() -> None:
    ap = argparse.ArgumentParser(description="Table 1 from one or more runs.jsonl files")
    ap.add_argument("--runs", type=Path, action="append", required=True, help="a runs.jsonl (repeatable)")
    ap.add_argument("--out", type=Path, required=True, help="the Markdown file to write (JSON beside it)")
    ap.add_argument("--model", action="append", default=None,
                    help="a recorded model to show, as NAME or NAME=SHOWN (repeatable; default: every model)")
    args = ap.parse_args()
    models = None if args.model is None else dict(m.split("=", 1) if "=" in m else (m, m) for m in args.model)
    missing = [p for p in args.runs if not p.is_file()]
    if missing:
        raise SystemExit(f"error: no such runs file: {missing[0]}")
    command = (".venv/bin/python -m experiments.translation.summary " + " ".join(f"--runs {p}" for p in args.runs)
               + "".join(f" --model {m}" for m in args.model or ()) + f" --out {args.out}")
    md = summarize(args.runs, args.out, command, "as recorded with each fold (the commands in each runs file's folder)",
                   models=models)
    print(md.read_text())


if __name__ == "__main__":
    main()
