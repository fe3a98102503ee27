"""Decode-only probe: two recipes' kept fold networks as one ensemble.

v3 (1,000 synthetic pairs a member) beat v2 (200) on leave-trees-out but lost to it on the
first cross-validation fold. This asks, without training anything, whether an ensemble of both
recipes' members keeps the better of each: for every fold both kept (`--keep-networks` folders
of `python -m experiments.translation`), it decodes the held-out descriptions with recipe A's
members, B's, and all of them together (with A's and with B's learned findings), and appends one
line per fold to `--out`. Members with the same seed but another synthetic count are different
networks, so an 8-member mix is confounded with ensemble size: this is a probe, not a verdict.

    PYTHONPATH=src:. .venv/bin/python -m experiments.translation.ensemble_probe --domain taxi \
        --a /work/scratch/v2_nets --b /work/scratch/v3_nets --out results/translation/ensemble_probe/runs.jsonl

With `--mix` instead of `--a` and `--b`, it reads the kept networks of one recipe whose members
alternate two synthetic counts (v3-mix200: even members 1,000 pairs, odd members 200) and
decodes each fold with four members of each kind, four alternating members (0-3: two of each)
and all eight, all with the fold's own learned findings. At four members the mix stands beside
its two pure halves at the same ensemble size, which the two-recipe probe could not do.

    PYTHONPATH=src:. .venv/bin/python -m experiments.translation.ensemble_probe --domain taxi \
        --mix /work/scratch/mix_nets --out results/translation/ensemble_probe/mix.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Optional

import torch

from experiments.translation.evaluate import PROTOCOL_ROUNDS, score
from nl2policy.language.corpus import load_corpus
from nl2policy.language.findings import FindingsModel
from nl2policy.language.models.config import MODELS
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.translator import TrainedTranslator


def fold_key(path: Path) -> str:
    """'taxi-v2-synth1000-trees-r0-f3.pt' -> 'trees-r0-f3' (the fold key ends every kept file's name)."""
    parts = path.stem.split("-")
    return "-".join(parts[-3:]) if parts[-2].startswith("r") else "-".join(parts[-2:])


def held_out(domain: str, kept: dict, key: str) -> tuple[list, list]:
    """The kept fold's held-out descriptions and their gold trees."""
    specs = load_corpus(domain, rounds=PROTOCOL_ROUNDS[key.split("-")[0]])
    return [specs[i].description for i in kept["test"]], [specs[i].tree for i in kept["test"]]


def tree_accuracy(domain: str, words: list, nets: list, findings: Optional[dict], texts: list, golds: list,
                  cache: MiniLMCache, length_norm: float = 0.0) -> float:
    """Exact tree accuracy of `nets` decoded as one ensemble with v3's decoding (beam 4, findings weight 1;
    `findings` None: decoded without findings), the beam ranked with `length_norm`."""
    cfg = dataclasses.replace(MODELS["v3"], ensemble=len(nets), findings_cost=1.0 if findings else 0.0,
                              length_norm=length_norm)
    model = TrainedTranslator.from_states(domain, "v3", cfg, words, nets, cache)
    if findings:
        model.findings = FindingsModel.from_state(findings, cache)
    return score(domain, [t for t, _ in model.predict(texts)], golds)["tree_acc"]


def append_line(out: Path, line: dict) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("a") as f:
        f.write(json.dumps(line) + "\n")
    print(json.dumps(line))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", required=True)
    parser.add_argument("--a", type=Path, help="kept networks of recipe A (a folder)")
    parser.add_argument("--b", type=Path, help="kept networks of recipe B (a folder)")
    parser.add_argument("--mix", type=Path, help="kept networks of one recipe whose members alternate two synthetic counts")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--no-findings", action="store_true",
                        help="with --a and --b: decode without learned findings, members' sums and means per node")
    args = parser.parse_args()
    mix_alone = args.mix is not None and args.a is None and args.b is None
    pair_alone = args.mix is None and args.a is not None and args.b is not None
    if not (mix_alone or pair_alone):
        parser.error("give either --a and --b, or --mix")
    torch.set_num_threads(1)
    cache = MiniLMCache()
    done = set()
    if args.out.is_file():
        done = {(r["domain"], r["fold"]) for r in map(json.loads, args.out.read_text().splitlines())}
    if args.mix:
        return probe_mix(args.domain, args.mix, args.out, done, cache)
    a_files = {fold_key(p): p for p in args.a.glob(f"{args.domain}-*.pt")}
    for b_path in sorted(args.b.glob(f"{args.domain}-*.pt")):
        key = fold_key(b_path)
        if key not in a_files or (args.domain, key) in done:
            continue
        a, b = (torch.load(p, weights_only=False) for p in (a_files[key], b_path))
        if a["train"] != b["train"] or a["test"] != b["test"] or a["words"] != b["words"]:
            raise SystemExit(f"{key}: the two folders' networks are not of the same fold")
        texts, golds = held_out(args.domain, b, key)
        line = {"domain": args.domain, "fold": key, "n": len(texts), "a_model": a["name"], "b_model": b["name"]}
        variants = [("a", a["nets"], a["findings"], 0.0), ("b", b["nets"], b["findings"], 0.0),
                    ("a+b, b's findings", a["nets"] + b["nets"], b["findings"], 0.0),
                    ("a+b, a's findings", a["nets"] + b["nets"], a["findings"], 0.0)]
        if args.no_findings:  # the same members decoded without findings, summed and per-node ranking
            variants = [(label, nets, None, norm) for norm in (0.0, 1.0)
                        for label, nets in ((f"a{', mean per node' * bool(norm)}", a["nets"]),
                                            (f"b{', mean per node' * bool(norm)}", b["nets"]),
                                            (f"a+b{', mean per node' * bool(norm)}", a["nets"] + b["nets"]))]
        for label, nets, findings, norm in variants:
            line[label] = tree_accuracy(args.domain, b["words"], nets, findings, texts, golds, cache, norm)
        append_line(args.out, line)


def probe_mix(domain: str, folder: Path, out: Path, done: set, cache: MiniLMCache) -> None:
    """Each kept fold of an alternating-count recipe decoded by subsets of its members (module docstring)."""
    for path in sorted(folder.glob(f"{domain}-*.pt")):
        key = fold_key(path)
        if (domain, key) in done:
            continue
        kept = torch.load(path, weights_only=False)
        nets = kept["nets"]
        if len(nets) < 8:
            raise SystemExit(f"{path}: {len(nets)} networks; the mix probe needs 8 (alternating synthetic counts)")
        texts, golds = held_out(domain, kept, key)
        line = {"domain": domain, "fold": key, "n": len(texts), "model": kept["name"]}
        for label, members in (("even 4 (1000 synthetic)", [0, 2, 4, 6]), ("odd 4 (200 synthetic)", [1, 3, 5, 7]),
                               ("first 4 (alternating)", [0, 1, 2, 3]), ("all 8", list(range(8)))):
            line[label] = tree_accuracy(domain, kept["words"], [nets[m] for m in members], kept["findings"], texts, golds, cache)
        append_line(out, line)


if __name__ == "__main__":
    main()
