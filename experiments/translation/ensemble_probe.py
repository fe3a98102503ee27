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
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

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


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", required=True)
    parser.add_argument("--a", type=Path, required=True, help="kept networks of recipe A (a folder)")
    parser.add_argument("--b", type=Path, required=True, help="kept networks of recipe B (a folder)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cache = MiniLMCache()
    done = set()
    if args.out.is_file():
        done = {(r["domain"], r["fold"]) for r in map(json.loads, args.out.read_text().splitlines())}
    a_files = {fold_key(p): p for p in args.a.glob(f"{args.domain}-*.pt")}
    for b_path in sorted(args.b.glob(f"{args.domain}-*.pt")):
        key = fold_key(b_path)
        if key not in a_files or (args.domain, key) in done:
            continue
        a, b = (torch.load(p, weights_only=False) for p in (a_files[key], b_path))
        if a["train"] != b["train"] or a["test"] != b["test"] or a["words"] != b["words"]:
            raise SystemExit(f"{key}: the two folders' networks are not of the same fold")
        specs = load_corpus(args.domain, rounds=PROTOCOL_ROUNDS[key.split("-")[0]])
        texts = [specs[i].description for i in b["test"]]
        golds = [specs[i].tree for i in b["test"]]
        line = {"domain": args.domain, "fold": key, "n": len(texts), "a_model": a["name"], "b_model": b["name"]}
        for label, nets, findings in (("a", a["nets"], a["findings"]), ("b", b["nets"], b["findings"]),
                                      ("a+b, b's findings", a["nets"] + b["nets"], b["findings"]),
                                      ("a+b, a's findings", a["nets"] + b["nets"], a["findings"])):
            cfg = dataclasses.replace(MODELS["v3"], ensemble=len(nets))  # v3's decoding: beam 4, findings weight 1
            model = TrainedTranslator.from_states(args.domain, "v3", cfg, b["words"], nets, cache)
            model.findings = FindingsModel.from_state(findings, cache)
            line[label] = score(args.domain, [t for t, _ in model.predict(texts)], golds)["tree_acc"]
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with args.out.open("a") as f:
            f.write(json.dumps(line) + "\n")
        print(json.dumps(line))


if __name__ == "__main__":
    main()
