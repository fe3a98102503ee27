"""Search error or model error? For each translation a fold's networks got wrong, is the gold tree
ranked above the one returned by the model's own score (then a wider or better search would find
it), or below (then only a better reading of the text would)?

    .venv/bin/python -m experiments.translation.search_errors --domain taxi --folds NETS \
        --fold-model v7 --out results/translation/nwnt/search-errors-taxi.md

NETS is a `--keep-networks` folder of the translation experiment. The gold tree's score comes from
decoding held to it, slot by slot (decoding.search with an `allow` that leaves only the gold token),
so it is the very score the beam ranks by: the sum of its nodes' log-probabilities divided by its
node count (`length_norm`). Also reported: whether the gold tree is among the finished hypotheses
of a 16-wide beam, the ceiling of any reranker of that beam.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

import torch

from experiments.checks import before_work
from experiments.clarify import load_networks, questions_in
from experiments.translation.evaluate import PROTOCOL_ROUNDS
from nl2policy.console import out_dir_or_fail, out_file_or_fail
from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.decoding import ranking_score, search
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.translator import TrainedTranslator, collate
from nl2policy.trees import Tree, to_tokens

WIDE = 16


@torch.inference_mode()
def judge(translator: TrainedTranslator, text: str, gold: Tree) -> dict:
    """One description: the returned tree, and where the gold tree stands against it (`hypotheses`,
    called first, puts the networks in eval mode for the held decoding too)."""
    gold_tokens = to_tokens(gold)
    best = translator.hypotheses(text)[0]
    pred_tokens = to_tokens(best[0])
    norm = translator.decoding("length_norm")

    def only_gold(prefix, slot):
        return {gold_tokens[len(prefix)]} if len(prefix) < len(gold_tokens) else set()

    forced = search(translator, collate([translator.encode(text)]), [text], None, [only_gold], 1)[0][0]
    wide = translator.hypotheses(text, width=WIDE)
    gold_score, pred_score = ranking_score(forced[2], len(gold_tokens), norm), ranking_score(best[2], len(pred_tokens), norm)
    return {"right": pred_tokens == gold_tokens, "search_error": gold_score > pred_score,
            "gold_score": gold_score, "pred_score": pred_score,
            "gold_nodes": len(gold_tokens), "pred_nodes": len(pred_tokens),
            "in_wide_beam": any(h[0] is not None and to_tokens(h[0]) == gold_tokens for h in wide)}


def main(argv: Optional[list[str]] = None) -> None:
    parser = argparse.ArgumentParser(description="Are a fold's translation errors search errors or model errors?")
    parser.add_argument("--domain", required=True)
    parser.add_argument("--folds", type=Path, required=True, help="a --keep-networks folder")
    parser.add_argument("--fold-model", required=True, help="the model name of the folds to read")
    parser.add_argument("--protocol", default="new")
    parser.add_argument("--out", type=Path, required=True, help="the report (markdown)")
    args = parser.parse_args(argv)
    before_work(out_dir_or_fail, args.out.parent, "--out's")  # before the decoding, not after it
    before_work(out_file_or_fail, args.out)
    torch.set_num_threads(1)
    get_domain(args.domain)
    paths = sorted(args.folds.glob(f"{args.domain}-{args.fold_model}-{args.protocol}-*.pt"))
    if not paths:
        parser.error(f"no {args.fold_model} {args.protocol} fold networks of {args.domain} in {args.folds}")
    specs = load_corpus(args.domain, rounds=PROTOCOL_ROUNDS[args.protocol])
    cache = MiniLMCache()
    errors, n = [], 0
    for path in paths:
        saved = torch.load(path, weights_only=False)
        translator = load_networks(saved, cache).translator
        for i in saved["test"]:
            n += 1
            row = judge(translator, specs[i].description, specs[i].tree)
            if not row["right"]:
                errors.append({"fold": path.stem, "id": specs[i].id, "questions": questions_in(specs[i].tree, args.domain), **row})
        print(f"{path.stem}: {len(errors)} errors so far of {n}", file=sys.stderr)
    command = "python -m experiments.translation.search_errors " + " ".join(argv if argv is not None else sys.argv[1:])
    lines = ["# Search errors or model errors", "", f"Made by: `{command}`  ",
             f"Folds: {', '.join(p.stem for p in paths)}; {n} held-out descriptions, {len(errors)} translated wrong.", "",
             "| | wrong | gold ranked above the returned tree (search error) | gold ranked below (model error) "
             f"| gold in a {WIDE}-wide beam |", "|---|---:|---:|---:|---:|"]
    for label, group in (("all", errors), ("trees of 4+ questions", [e for e in errors if e["questions"] >= 4])):
        searched = sum(e["search_error"] for e in group)
        lines.append(f"| {label} | {len(group)} | {searched} | {len(group) - searched} | {sum(e['in_wide_beam'] for e in group)} |")
    lines += ["", "Each error: the beam's score per node of the gold tree and of the returned one (nodes).", "",
              "| fold | description | questions in the tree | gold | returned |", "|---|---|---:|---:|---:|"]
    lines += [f"| {e['fold']} | {e['id']} | {e['questions']} | {e['gold_score']:.3f} ({e['gold_nodes']}) | "
              f"{e['pred_score']:.3f} ({e['pred_nodes']}) |" for e in errors]
    try:
        args.out.write_text("\n".join(lines) + "\n")
    except OSError as exc:
        parser.error(f"cannot write the report to {args.out}: {exc.strerror or exc}")
    print("\n".join(lines[:9]))


if __name__ == "__main__":
    main()
