"""Does the ensemble's disagreement say more about a translation's chance of being right than the
averaged probability does? The translator's confidence is the tree's probability under the
members' averaged step probabilities. Written before looking at any result, one alternative is
compared with it: the geometric mean over members of each member's own probability of the same
tree, which a member that reads the text otherwise pulls down. (Per node, a geometric mean is at
most the arithmetic one, so the alternative is never above today's confidence.)

    .venv/bin/python -m experiments.translation.confidence_probe --domain highway --folds NETS \
        --fold-model v7 --out results/translation/nwnt/confidence-probe-highway.md

Reported per signal: right / confident at the threshold 0.6 and the share confident; the
precision at the coverage today's confidence has at 0.6 (the same number of translations,
ranked by each signal: a comparison free of any threshold); and the area under the ROC curve of
right against wrong.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Optional

import torch

from experiments.clarify import load_networks
from experiments.translation.evaluate import PROTOCOL_ROUNDS
from nl2policy.domains import get_domain
from nl2policy.language.clarify import ASK_BELOW
from nl2policy.language.corpus import load_corpus
from nl2policy.language.decoding import search, tree_probability
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.translator import TrainedTranslator, collate
from nl2policy.trees import Tree, to_tokens

SIGNALS = ("averaged (today)", "geometric mean of members")


def held_probability(translator: TrainedTranslator, text: str, tree: Tree) -> float:
    """The translator's probability of `tree` for `text`: decoding held to its tokens, slot by slot."""
    tokens = to_tokens(tree)

    def only(prefix, slot):
        return {tokens[len(prefix)]} if len(prefix) < len(tokens) else set()

    held = search(translator, collate([translator.encode(text)]), [text], None, [only], 1)[0][0]
    assert held[0] == tree, "decoding held to a tree built another one"
    return tree_probability(held[1])


@torch.inference_mode()
def signals(translator: TrainedTranslator, members: list[TrainedTranslator], text: str) -> tuple[Tree, dict[str, float]]:
    """The returned tree and each signal's value for it."""
    tree, node_probs, _ = translator.hypotheses(text)[0]
    logs = [math.log(max(held_probability(m, text, tree), 1e-300)) for m in members]
    return tree, {SIGNALS[0]: tree_probability(node_probs), SIGNALS[1]: math.exp(sum(logs) / len(logs))}


def auroc(scores: list[float], right: list[bool]) -> float:
    """The chance that a right translation scores above a wrong one (ties count half)."""
    pos = [s for s, r in zip(scores, right) if r]
    neg = [s for s, r in zip(scores, right) if not r]
    if not pos or not neg:
        return float("nan")
    return sum((p > n) + 0.5 * (p == n) for p in pos for n in neg) / (len(pos) * len(neg))


def report(rows: list[dict], command: str, folds: list[str]) -> list[str]:
    n = len(rows)
    right = [r["right"] for r in rows]
    covered = sum(r[SIGNALS[0]] >= ASK_BELOW for r in rows)
    lines = ["# Confidence: the averaged probability against the members' geometric mean", "", f"Made by: `{command}`  ",
             f"Folds: {', '.join(folds)}; {n} held-out descriptions, {sum(right)} translated right.", "",
             f"| signal | right / confident at {ASK_BELOW} | confident share | precision of the top {covered} "
             "(today's coverage) | AUROC |", "|---|---:|---:|---:|---:|"]
    for name in SIGNALS:
        scores = [r[name] for r in rows]
        conf = [r for r in rows if r[name] >= ASK_BELOW]
        top = sorted(rows, key=lambda r: -r[name])[:covered]
        lines.append(f"| {name} | {sum(r['right'] for r in conf)} / {len(conf)} | {100 * len(conf) / n:.1f} % | "
                     f"{100 * sum(r['right'] for r in top) / max(1, covered):.1f} % | {auroc(scores, right):.3f} |")
    lines += ["", "Wrong translations with either signal at or above the threshold:", "",
              "| fold | description | " + " | ".join(SIGNALS) + " |", "|---|---|---:|---:|"]
    lines += [f"| {r['fold']} | {r['id']} | " + " | ".join(f"{r[s]:.3f}" for s in SIGNALS) + " |"
              for r in rows if not r["right"] and max(r[s] for s in SIGNALS) >= ASK_BELOW]
    return lines


def main(argv: Optional[list[str]] = None) -> None:
    parser = argparse.ArgumentParser(description="The averaged confidence against the members' geometric mean")
    parser.add_argument("--domain", required=True)
    parser.add_argument("--folds", type=Path, required=True, help="a --keep-networks folder")
    parser.add_argument("--fold-model", required=True, help="the model name of the folds to read")
    parser.add_argument("--protocol", default="new")
    parser.add_argument("--out", type=Path, required=True, help="the report (markdown)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    get_domain(args.domain)
    paths = sorted(args.folds.glob(f"{args.domain}-{args.fold_model}-{args.protocol}-*.pt"))
    if not paths:
        parser.error(f"no {args.fold_model} {args.protocol} fold networks of {args.domain} in {args.folds}")
    specs = load_corpus(args.domain, rounds=PROTOCOL_ROUNDS[args.protocol])
    cache = MiniLMCache()
    rows = []
    for path in paths:
        saved = torch.load(path, weights_only=False)
        translator = load_networks(saved, cache).translator
        members = [replace(translator, nets=[net], findings=None) for net in translator.nets]
        for i in saved["test"]:
            tree, values = signals(translator, members, specs[i].description)
            rows.append({"fold": path.stem, "id": specs[i].id, "right": to_tokens(tree) == to_tokens(specs[i].tree), **values})
        print(f"{path.stem}: {len(rows)} descriptions", file=sys.stderr)
    command = "python -m experiments.translation.confidence_probe " + " ".join(argv if argv is not None else sys.argv[1:])
    lines = report(rows, command, [p.stem for p in paths])
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")
    except OSError as exc:
        parser.error(f"cannot write the report to {args.out}: {exc.strerror or exc}")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
