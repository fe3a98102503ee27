"""Can the ask threshold be set on held-out writers? A cross-fitted check of the clarify rows.

    .venv/bin/python -m experiments.clarify_threshold --rows results/clarify/v6-taxi/rows.jsonl \
        --rows results/clarify/v6-highway/rows.jsonl --precision 0.97 --out results/clarify/threshold-v6.md

The translator asks nothing when its confidence is at or above a threshold (clarify.ASK_BELOW).
Read off the rows of a simulated-user run, the lowest threshold at which the translations left
unasked are still `--precision` right would be chosen on the very descriptions it is scored on.
Here each writer is held out in turn (the rows of every domain given, pooled by writer: the
recipe has one threshold): the threshold is the lowest confidence at which the other writers'
translations at or above it are at least `--precision` exact, and the held-out writer's rows are
scored with it. The report: per domain, the share left unasked and their exact accuracy, cross-fitted,
beside the current threshold's; and the threshold all writers together would give.

Only the confidence before any answer is read (rows' `confidence[0]`, `exact[0]`): what decides
whether anything is asked at all.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Optional

from nl2policy.language.clarify import ASK_BELOW

Row = tuple[str, str, float, bool]
"""(domain, writer, confidence before answers, exact before answers)."""


def read_rows(path: Path) -> list[Row]:
    """A clarify run's rows: the domain as recorded (rows written before it was, from `--folds` runs
    only: the fold's, `taxi-v5-new-f0` -> taxi), the writer the description id's prefix (`memo-017` -> memo)."""
    out = []
    for line in path.read_text().splitlines():
        if line.strip():
            r = json.loads(line)
            out.append((r.get("domain") or r["fold"].split("-")[0], r["id"].rsplit("-", 1)[0], float(r["confidence"][0]), bool(r["exact"][0])))
    return out


def lowest_threshold(rows: list[Row], precision: float) -> Optional[float]:
    """The lowest confidence t such that the rows at or above t are at least `precision` exact
    (None: no such t)."""
    best, right = None, 0
    for i, (_, _, p, exact) in enumerate(sorted(rows, key=lambda r: -r[2])):
        right += exact
        if right / (i + 1) >= precision:
            best = p
    return best


def unasked(rows: list[Row], threshold: Optional[float]) -> tuple[int, int]:
    """(rows at or above the threshold, of them exact)."""
    if threshold is None:
        return 0, 0
    kept = [r for r in rows if r[2] >= threshold]
    return len(kept), sum(r[3] for r in kept)


def main(argv: Optional[list[str]] = None) -> None:
    parser = argparse.ArgumentParser(description="Cross-fitted check of the ask threshold over held-out writers.")
    parser.add_argument("--rows", type=Path, action="append", required=True, help="a clarify run's rows.jsonl (repeatable)")
    parser.add_argument("--precision", type=float, default=0.97)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    rows = [r for path in args.rows for r in read_rows(path)]
    writers = sorted({r[1] for r in rows})
    chosen = {w: lowest_threshold([r for r in rows if r[1] != w], args.precision) for w in writers}
    by_domain: dict[str, list[Row]] = defaultdict(list)
    for r in rows:
        by_domain[r[0]].append(r)
    pct = lambda a, b: f"{100 * a / b:.1f}" if b else "-"
    command = "python -m experiments.clarify_threshold " + " ".join(argv if argv is not None else sys.argv[1:])
    lines = ["# The ask threshold, set on held-out writers\n", f"Made by: `{command}`  ",
             f"Target: the translations left unasked at least {100 * args.precision:.0f} % exact. Each writer's "
             "threshold is chosen on the other writers' rows (all domains pooled) and scored on their own.\n",
             "| writer | threshold from the others |", "|---|---:|"]
    lines += [f"| {w} | {'-' if chosen[w] is None else f'{chosen[w]:.3f}'} |" for w in writers]
    lines += ["", "| domain | n | cross-fitted: unasked % | exact % of unasked | at "
              f"{ASK_BELOW}: unasked % | exact % of unasked |", "|---|---:|---:|---:|---:|---:|"]
    for domain, rs in sorted(by_domain.items()):
        kept = right = 0
        for w in writers:
            k, e = unasked([r for r in rs if r[1] == w], chosen[w])
            kept, right = kept + k, right + e
        k0, e0 = unasked(rs, ASK_BELOW)
        lines.append(f"| {domain} | {len(rs)} | {pct(kept, len(rs))} | {pct(right, kept)} | {pct(k0, len(rs))} | {pct(e0, k0)} |")
    pooled = lowest_threshold(rows, args.precision)
    lines += ["", f"All writers together: {'-' if pooled is None else f'{pooled:.3f}'} (what shipping a fitted threshold would use).\n"]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines))
    print(args.out.read_text())


if __name__ == "__main__":
    main()
