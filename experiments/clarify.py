"""The simulated user: translate each description, answer every question the translator asks from
the gold tree, and score the tree after 0, 1, 2 ... answers.

    .venv/bin/python -m experiments.clarify --domain taxi --data FILE.jsonl --max-questions 3 --out DIR
    .venv/bin/python -m experiments.clarify --domain taxi --folds NETS --max-questions 3 --out DIR
    .venv/bin/python -m experiments.clarify --domain taxi --rows DIR/rows.jsonl [--rows ...] \
        [--only-folds new-f0,new-f1] --max-questions 3 --out DIR2

FILE holds {"description", "tree"} rows, translated by --model (a model file; default: the shipped
one). --folds decodes instead the fold networks a translation experiment kept (--keep-networks),
each on its own held-out descriptions: with the folds of new writers with new trees (NWNT), the
translator has seen neither the writer nor the tree of any description it is asked about.

Writes DIR/summary.json (`exact_by_questions` and `policy_by_questions`: accuracy in % after at
most 0, 1, ... answers; `mean_questions`; `asked_none_share` and `asked_none_exact` in %; `n`; the
same by the number of questions in the gold tree and by fold), DIR/summary.md and DIR/rows.jsonl
(each description's questions, answers and trees).

--rows translates nothing: it summarizes rows written before (committed rows.jsonl files), merged
over the files given (a row repeated word for word is kept once) and kept to the folds whose names
end as --only-folds says. It puts figures of runs made in different sessions (one fold each, say)
in one table, and compares two translators on the same folds, from committed files alone.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Optional, Sequence

import torch

import experiments.translation.baselines  # noqa: F401  (registers the lab's model names)
from experiments.checks import before_work
from experiments.translation.evaluate import PROTOCOL_ROUNDS, trained_config
from nl2policy.console import out_dir_or_fail
from nl2policy.domains import get_domain
from nl2policy.language.clarify import Answer, agrees, situations
from nl2policy.language.corpus import load_corpus
from nl2policy.language.findings import FindingsModel
from nl2policy.language.models.config import MODELS, networks_config
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.translate import LoadedModel, find_model, translate_with
from nl2policy.language.translator import TrainedTranslator
from nl2policy.trees import Tree, parse_tree, to_tokens
from nl2policy.trees.parse import validate


def load_networks(data: dict, cache: MiniLMCache, decode_as: Optional[str] = None) -> LoadedModel:
    """A loaded shipped model file or fold's kept networks, decoded as the config that trained
    them (`trained_config`). `decode_as`: a registered model that trains the same networks,
    whose decoding settings (beam, findings, ranking) are used instead."""
    cfg = trained_config(data)
    if cfg is None:
        raise ValueError(f"nothing records what trained these networks (model {data['name']!r} is not registered)")
    if decode_as is not None:
        if decode_as not in MODELS:
            raise ValueError(f"no model is registered as {decode_as!r}")
        if networks_config(MODELS[decode_as]) != networks_config(cfg):
            raise ValueError(f"{decode_as} does not train these networks")
        cfg = MODELS[decode_as]
    translator = TrainedTranslator.from_states(data["domain"], data["name"], cfg, data["words"], data["nets"], cache)
    if data.get("findings") is not None:
        translator.findings = FindingsModel.from_state(data["findings"], cache)
    lexicon = {d: set(ws) for d, ws in data["lexicon"].items()} if data.get("lexicon") else {}
    return LoadedModel(translator, lexicon)


def questions_in(tree: Tree, domain: str) -> int:
    return sum(t in get_domain(domain).vocab.questions for t in to_tokens(tree))


def simulate(loaded: LoadedModel, domain: str, text: str, gold: Tree, max_questions: int) -> dict:
    """Answer each question from `gold` until none is asked or `max_questions` were."""
    d = get_domain(domain)
    allowed = set(situations(domain))
    answers: list[Answer] = []
    result = translate_with(loaded, domain, text, answers, max_questions, check_asked=False)
    trees, asked = [result.tree], []
    confidence = [result.confidence]
    while result.questions and len(answers) < max_questions:
        question = result.questions[0]
        assert question.situation in allowed, question.situation  # only situations the domain allows
        answers.append(Answer(question.situation, gold.act(dict(question.situation))))
        asked.append(question.text)
        result = translate_with(loaded, domain, text, answers, max_questions, check_asked=False)
        assert agrees(result.tree, answers), "a tree returned after answers acts otherwise"
        trees.append(result.tree)
        confidence.append(result.confidence)
    for tree in trees:
        validate(tree, d.vocab)
    trees += [trees[-1]] * (max_questions + 1 - len(trees))
    return {"questions": asked, "answers": [a.to_json() for a in answers], "confidence": [round(c, 4) for c in confidence],
            "trees": [" ".join(to_tokens(t)) for t in trees], "gold": " ".join(to_tokens(gold)),
            "exact": [t == gold for t in trees], "policy": [d.same_policy(t, gold) for t in trees],
            "gold_questions": questions_in(gold, domain)}


def summarize(rows: list[dict], max_questions: int) -> dict:
    n = len(rows)
    pct = lambda xs: round(100 * sum(xs) / len(xs), 2) if xs else None
    none = [r for r in rows if not r["questions"]]
    out = {"n": n, "exact_by_questions": [pct([r["exact"][j] for r in rows]) for j in range(max_questions + 1)],
           "policy_by_questions": [pct([r["policy"][j] for r in rows]) for j in range(max_questions + 1)],
           "mean_questions": round(sum(len(r["questions"]) for r in rows) / n, 3) if n else None,
           "asked_none_share": pct([not r["questions"] for r in rows]), "asked_none_exact": pct([r["exact"][0] for r in none])}
    groups = defaultdict(list)
    for r in rows:
        groups[min(r["gold_questions"], 5)].append(r)
    out["by_tree_questions"] = {("5+" if k == 5 else str(k)): {
        "n": len(g), "exact_by_questions": [pct([r["exact"][j] for r in g]) for j in range(max_questions + 1)],
        "mean_questions": round(sum(len(r["questions"]) for r in g) / len(g), 2)} for k, g in sorted(groups.items())}
    return out


def fold_matches(fold: str, wanted: Optional[Sequence[str]]) -> bool:
    """A fold named e.g. "taxi-v7-new-f3" is wanted as "new-f3", "f3" or its whole name."""
    return wanted is None or any(fold == w or fold.endswith("-" + w) for w in wanted)


def merge_rows(files: Sequence[Path], wanted: Optional[Sequence[str]], domain: str) -> list[dict]:
    """The rows of `files` in order, each (fold, id) once, kept to the `wanted` folds. Raises
    ValueError for a file that is not rows of this command, a row of another domain, or one
    (fold, id) with two different results: two runs of one fold that disagree are not merged."""
    seen: dict[tuple[str, str], dict] = {}
    for path in files:
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"cannot read {path}: {exc}") from None
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
                key = (row["fold"], row["id"])
                complete = all(k in row for k in ("exact", "policy", "questions", "gold_questions"))
            except (json.JSONDecodeError, TypeError, KeyError):
                complete = False
            if not complete:
                raise ValueError(f"{path}:{number} is not a row of experiments.clarify")
            if row.get("domain", domain) != domain:
                raise ValueError(f"{path}:{number} is a {row['domain']} row, not {domain}")
            if key in seen and seen[key] != row:
                raise ValueError(f"{path}:{number}: fold {key[0]}, description {key[1]} has another result in an "
                                 "earlier file; merge the runs of one fold from one file")
            if fold_matches(row["fold"], wanted):
                seen.setdefault(key, row)
    return list(seen.values())


def markdown(summary: dict, command: str, max_questions: int) -> str:
    heads = " | ".join(f"after {j}" for j in range(max_questions + 1))
    bar = "|---" * (max_questions + 4)
    lines = [f"# Asking when unsure: the simulated user\n", f"Made by: `{command}`  ",
             "Each question is answered from the gold tree; accuracy (%) of the tree after at most k answers.\n",
             f"| | n | {heads} | questions asked (mean) |", bar + "|",
             f"| exact | {summary['n']} | " + " | ".join(f"{x:.1f}" for x in summary["exact_by_questions"])
             + f" | {summary['mean_questions']:.2f} |",
             f"| policy | {summary['n']} | " + " | ".join(f"{x:.1f}" for x in summary["policy_by_questions"]) + " | |", "",
             f"Nothing asked for {summary['asked_none_share']:.1f} % of descriptions; of those, "
             f"{summary['asked_none_exact'] if summary['asked_none_exact'] is not None else '-'} % exact.\n",
             "By the number of questions in the gold tree (exact %):\n",
             f"| questions in the tree | n | {heads} | asked (mean) |", bar + "|"]
    for k, g in summary["by_tree_questions"].items():
        lines.append(f"| {k} | {g['n']} | " + " | ".join(f"{x:.1f}" for x in g["exact_by_questions"]) + f" | {g['mean_questions']:.2f} |")
    if "by_fold" in summary:
        lines += ["", "By fold (exact % after 0 and after at most "
                  f"{max_questions} answers):", "", "| fold | n | after 0 | after max | asked (mean) |", "|---|---:|---:|---:|---:|"]
        for fold, f in summary["by_fold"].items():
            lines.append(f"| {fold} | {f['n']} | {f['exact_by_questions'][0]:.1f} | {f['exact_by_questions'][-1]:.1f} | "
                         f"{f['mean_questions']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: Optional[list[str]] = None) -> None:
    parser = argparse.ArgumentParser(description="Simulated-user evaluation of asking when unsure.")
    parser.add_argument("--domain", required=True)
    parser.add_argument("--data", type=Path, help='JSONL of {"description", "tree"} rows')
    parser.add_argument("--model", type=Path, help="model file for --data (default: the shipped model)")
    parser.add_argument("--folds", type=Path, help="a --keep-networks folder: each fold's networks on its own test specs")
    parser.add_argument("--fold-model", default=None, help="only the folds of this model name (default: all)")
    parser.add_argument("--protocol", default="new", help="only the folds of this protocol (default: new)")
    parser.add_argument("--decode-as", default=None, help="with --folds: decode the kept networks with this registered "
                                                       "model's decoding settings (a model that trains the same networks)")
    parser.add_argument("--rows", type=Path, action="append", help="summarize these rows.jsonl files (repeatable) "
                                                                     "instead of translating")
    parser.add_argument("--only-folds", default=None, help="with --rows: only these folds, comma-separated "
                                                          "(e.g. new-f0,new-f1)")
    parser.add_argument("--max-questions", type=int, default=3)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    get_domain(args.domain)
    if sum(x is not None for x in (args.data, args.folds, args.rows)) != 1:
        parser.error("give one of --data FILE (with --model), --folds DIR or --rows FILE")
    if args.only_folds is not None and args.rows is None:
        parser.error("--only-folds goes with --rows")
    command = "python -m experiments.clarify " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.rows is not None:
        wanted = [w.strip() for w in args.only_folds.split(",") if w.strip()] if args.only_folds else None
        if wanted is not None and (args.out / "rows.jsonl").resolve() in {p.resolve() for p in args.rows}:
            parser.error(f"--only-folds would drop the other folds' rows from {args.out / 'rows.jsonl'}: "
                         "write to another --out")
        try:
            rows = merge_rows(args.rows, wanted, args.domain)
        except ValueError as exc:
            parser.error(str(exc))
        if not rows:
            parser.error("no rows of the folds asked for in " + ", ".join(map(str, args.rows)))
        if any(len(r["exact"]) != args.max_questions + 1 for r in rows):
            parser.error(f"these rows were not made with --max-questions {args.max_questions}")
        save(parser, rows, args.out, args.max_questions, command)
        return
    before_work(out_dir_or_fail, args.out)  # before the translating, not after it
    cache = MiniLMCache()
    jobs: list[tuple[str, LoadedModel, list[tuple[str, Tree, str]]]] = []
    if args.folds is not None:
        specs = load_corpus(args.domain, rounds=PROTOCOL_ROUNDS[args.protocol])
        paths = sorted(args.folds.glob(f"{args.domain}-{args.fold_model or '*'}-{args.protocol}-*.pt"))
        if not paths:
            parser.error(f"no {args.protocol} fold networks of {args.domain} in {args.folds}")
        for path in paths:
            saved = torch.load(path, weights_only=False)
            try:
                loaded = load_networks(saved, cache, args.decode_as)
            except ValueError as exc:
                parser.error(f"{path}: cannot decode its networks ({exc})")
            jobs.append((path.stem, loaded,
                         [(specs[i].description, specs[i].tree, specs[i].id) for i in saved["test"]]))
    else:
        vocab = get_domain(args.domain).vocab
        rows = [json.loads(line) for line in args.data.read_text().splitlines() if line.strip()]
        model = args.model or find_model(args.domain)
        jobs.append(("data", load_networks(torch.load(model, weights_only=False), cache),
                     [(r["description"], parse_tree(r["tree"], vocab), r.get("id", str(i))) for i, r in enumerate(rows)]))
    all_rows = []
    for fold, loaded, items in jobs:
        rows = [{"fold": fold, "domain": args.domain, "id": key, **simulate(loaded, args.domain, text, gold, args.max_questions)}
                for text, gold, key in items]
        print(f"{fold}: exact {summarize(rows, args.max_questions)['exact_by_questions']}", file=sys.stderr)
        all_rows += rows
    save(parser, all_rows, args.out, args.max_questions, command)


def save(parser: argparse.ArgumentParser, rows: list[dict], out: Path, max_questions: int, command: str) -> None:
    """`write_summary`, with a folder that cannot be written said in one line (exit 2)."""
    try:
        write_summary(rows, out, max_questions, command)
    except OSError as exc:
        parser.error(f"cannot write the results to {out}: {exc.strerror or exc}")


def write_summary(rows: list[dict], out: Path, max_questions: int, command: str) -> None:
    """DIR/rows.jsonl, DIR/summary.json and DIR/summary.md; each file is written whole or left as
    it was (rows are read before, so --rows may name DIR/rows.jsonl itself)."""
    by_fold: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_fold[r["fold"]].append(r)
    summary = summarize(rows, max_questions)
    if len(by_fold) > 1:
        summary["by_fold"] = {k: {"n": len(v), "exact_by_questions": s["exact_by_questions"],
                                  "mean_questions": s["mean_questions"]}
                              for k, v in sorted(by_fold.items()) for s in [summarize(v, max_questions)]}
    summary["command"] = command
    out.mkdir(parents=True, exist_ok=True)
    texts = {"rows.jsonl": "".join(json.dumps(r) + "\n" for r in rows),
             "summary.json": json.dumps(summary, indent=1) + "\n", "summary.md": markdown(summary, command, max_questions)}
    for name, text in texts.items():
        tmp = out / f".{name}.tmp"
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(out / name)
    print(texts["summary.md"])

if __name__ == "__main__":
    main()
