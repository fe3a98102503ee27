"""Translator files read side by side on one set of fresh synthetic descriptions.

    python -m experiments.translation.fresh_pairs --domain lunar --pairs 200 --seed 4242 \
        --file shipped=src/nl2policy/domains/lunar/translator-v7.pt --file other=PATH ... \
        --findings-cost 0 --findings-cost 1 --out results/translation/lunar_reading.md

For a domain nobody has described yet (lunar) this is the only reading we can measure besides
leave-style-out: each file translates the same `--pairs` descriptions the generator writes with
`--seed` (a draw no training member used: members draw with seeds from 0 up), once with each
`--findings-cost` (how much the learned findings weigh in the beam; a decoding choice, so the same
networks are read both ways; without the option, each file as it decodes by its own recipe). What
it cannot tell: how people would describe the domain; the descriptions are the generator's own
styles, which every file trained on, and their trees are drawn as training drew its trees, so a
small tree may be one training described otherwise (leave-style-out holds trees out).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Optional

from experiments.checks import before_work


def _named_file(value: str) -> tuple[str, Path]:
    name, sep, path = value.partition("=")
    if not sep or not name or not path:
        raise argparse.ArgumentTypeError(f"expected NAME=PATH, got {value!r}")
    return name, Path(path)


def score(translator, domain: str, pairs: list, findings_cost: Optional[float]) -> dict:
    """Exact and policy matches of one translator's reading of `pairs` at one findings weight
    (None: its recipe's own)."""
    from experiments.translation.evaluate import score as fold_score
    from nl2policy.domains import get_domain

    translator.findings_cost = findings_cost if translator.findings is not None else 0.0
    decoded = translator.predict([text for text, _ in pairs])
    scored = fold_score(domain, [tree for tree, _ in decoded], [gold for _, gold in pairs])  # the lab's one scorer
    return {"model": translator.name, "epochs": translator.cfg.epochs, "synthetic": translator.cfg.synthetic,
            "findings": translator.findings is not None, "findings_cost": translator.decoding("findings_cost"),
            "exact": round(scored["tree_acc"] * scored["n"]), "policy": round(scored["policy_acc"] * scored["n"]),
            "example": translator.predict([get_domain(domain).example])[0][0] == get_domain(domain).example_tree}


def main(argv: Optional[list[str]] = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--domain", default="lunar")
    parser.add_argument("--pairs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--file", type=_named_file, action="append", required=True, help="NAME=PATH of a translator file")
    parser.add_argument("--findings-cost", type=float, action="append", default=None,
                        help="a weight of the learned findings in the beam (repeatable); default: each file's own")
    parser.add_argument("--out", type=Path, default=None, help="also write the table to this file")
    args = parser.parse_args(argv)
    from nl2policy.console import domain_or_fail, out_file_or_fail, seed_or_fail

    if args.pairs < 1:
        parser.error(f"--pairs must be at least 1, not {args.pairs}")
    before_work(seed_or_fail, args.seed)
    before_work(domain_or_fail, args.domain)
    if args.out is not None:
        before_work(out_file_or_fail, args.out)
    missing = [str(path) for _, path in args.file if not path.is_file()]
    if missing:
        parser.error(f"no translator file at {', '.join(missing)}")
    import torch

    from nl2policy.language.synthetic import synthetic_pairs
    from nl2policy.language.translate import load_model

    torch.set_num_threads(1)
    translators = []
    for name, path in args.file:  # every file read before any scoring: a bad one is one line, not a traceback later
        try:
            translators.append((name, load_model(path, args.domain).translator))
        except Exception as exc:  # a damaged, foreign or other domain's file
            parser.error(f"cannot read a translator from {path}: {type(exc).__name__}: {exc}")
    pairs = synthetic_pairs(args.domain, args.pairs, args.seed)
    costs = args.findings_cost or [None]
    lines = [f"# {args.domain}: translator files on {len(pairs)} fresh synthetic descriptions", "",
             f"Command: `python -m experiments.translation.fresh_pairs {shlex.join(sys.argv[1:] if argv is None else argv)}`",
             "", f"Descriptions: the generator's, seed {args.seed}. Example: the domain's example text read as its tree.", "",
             "| file | model | synthetic pairs a network | epochs | findings in the beam | exact | policy | example |",
             "|---|---|---:|---:|---:|---:|---:|---|"]
    for name, translator in translators:
        for cost in costs if translator.findings is not None else [None]:  # no findings: one reading
            row = score(translator, args.domain, pairs, cost)
            weight = f"{row['findings_cost']:g}" + (" (its own)" if cost is None else "") if row["findings"] else "- (none saved)"
            lines.append(f"| {name} | {row['model']} | {row['synthetic']} | {row['epochs']} | {weight} | {row['exact']} | "
                         f"{row['policy']} | {'right' if row['example'] else 'wrong'} |")
            print(lines[-1], flush=True)
    report = "\n".join(lines) + "\n"
    if args.out is not None:
        args.out.write_text(report)
    print(report)


if __name__ == "__main__":
    main()
