"""The translation experiment (Table 1): every translator under cross-validation, leave-writers-out,
leave-trees-out and new writers with new trees; resumable, one line per fold in runs.jsonl.

    .venv/bin/python -m experiments.translation --domain taxi --plan 'best:trees1' --out results/translation/trees

A lab harness, outside the product: it imports the package, the package never imports it.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from experiments.translation.evaluate import UnknownFold, fold_count, run_experiment
from experiments.translation.summary import summarize
from nl2policy.console import console, domain_or_fail, err
from experiments.grid import normalize_ray_flag, ray_failure, ray_option_help
from nl2policy.language.models.config import DEFAULT_MODEL, MODELS


def parse_plan(plan: str, domains: list[str], default_model: str) -> list[tuple[str, str, str, int]]:
    """'model:protocols;...' -> (domain, model, protocol, repeats) steps, in plan order. A model
    prefixed with 'DOMAIN/' runs for that domain only (a probe of one domain must not be listed as
    not run in the others); protocols are cvR (R repeats of 5-fold CV), treesR (R repeats of
    5-fold leave-trees-out on both corpus rounds), writers and new (each round-2 writer held out
    with every policy they describe), and cvbothR and writersboth (round 1's folds with round 2
    joining every training fold)."""
    alias = {"best": default_model, "single": "seq2tree-minilm-synth", "ablation": "seq2tree-minilm"}
    steps = []
    for part in plan.split(";"):
        name, sep, protocols = part.partition(":")
        only, _, name = name.rpartition("/")
        name = alias.get(name, name)
        if not sep or name not in MODELS:
            raise ValueError(f"plan part {part!r}: expected MODEL:PROTOCOLS with a model of {sorted(MODELS)}")
        if only and only not in domains:
            raise ValueError(f"plan part {part!r}: {only!r} is not one of the --domain options {domains}")
        for p in protocols.split(","):
            if p in ("writers", "new", "writersboth"):
                protocol, repeats = p, 1
            elif p.startswith("cvboth") and (p[6:] or "1").isdigit():
                protocol, repeats = "cvboth", int(p[6:] or 1)
            elif p.startswith("cv") and (p[2:] or "1").isdigit():
                protocol, repeats = "cv", int(p[2:] or 1)
            elif p.startswith("trees") and (p[5:] or "1").isdigit():
                protocol, repeats = "trees", int(p[5:] or 1)
            else:
                raise ValueError(f"plan part {part!r}: protocol {p!r} is not cvR, treesR, writers, new, cvbothR or writersboth")
            steps += [(d, name, protocol, repeats) for d in domains if not only or d == only]
    return steps


DEFAULT_PLAN = ("best:trees3,cvboth3,new,writersboth,cv3,writers;"
                "seq2seq:cv3,writers,trees3;seq2tree:cv3,writers,trees3;seq2tree-minilm:cv3,writers,trees3;"
                "han2tree:cv3,writers,trees3")
"""Table 1 (most important first: the experiment resumes, so what finished is kept)."""


def translation_experiment(
    domain: list[str] = typer.Option(["taxi", "highway"], help="Domains"),
    plan: str = typer.Option(DEFAULT_PLAN, help="model:protocols;... with cvR = R repeats of 5-fold CV, writers = leave-writers-out, "
                                               "treesR = leave-trees-out, new = new writers with new trees, cvbothR and "
                                               "writersboth = round 1's folds with round 2 in training; "
                                               "'best' = the default model (an ensemble of four), 'single' = one of its "
                                               "networks, 'ablation' = one network without synthetic data; "
                                               "DOMAIN/model runs for that domain only"),
    out: Path = typer.Option(Path("results/translation/table1"), help="Folder for runs.jsonl, translation.md/.json"),
    summarize_only: bool = typer.Option(False, help="Only rewrite the tables from the folds already in runs.jsonl"),
    workers: int = typer.Option(1, min=1, help="Processes training an ensemble's members side by side (one thread "
                                               "each): same results, less wall time on a machine with as many cores"),
    keep_networks: Optional[Path] = typer.Option(None, help="Also save each fold's networks in this folder, to study "
                                                            "decoding choices on them without retraining"),
    networks_from: Optional[Path] = typer.Option(None, help="A --keep-networks folder: a fold whose networks are there "
                                                           "(same fold, a model that trains the same networks) decodes "
                                                           "them instead of training"),
    ray: Optional[str] = typer.Option(None, "--ray", help=ray_option_help()),
    fold: list[str] = typer.Option([], help="Run only these fold keys (e.g. new-f1; repeatable): a candidate judged "
                                            "first on the hard folds; the rest can follow later, as the run resumes"),
) -> None:
    """Every translator's accuracy under each protocol (resumable): Table 1."""
    import torch

    torch.set_num_threads(1)
    for d in domain:
        domain_or_fail(d)
    try:
        steps = parse_plan(plan, domain, DEFAULT_MODEL)
    except ValueError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2)
    # run in plan order (most important first): the experiment resumes, so what finished is kept
    command = "python -m experiments.translation " + " ".join(f"--domain {d}" for d in domain) + f" --plan '{plan}' --out {out}" + "".join(f" --fold {k}" for k in fold)
    if summarize_only and not (out / "runs.jsonl").is_file():
        err.print(f"[red]error:[/red] no folds to summarise: {out / 'runs.jsonl'} does not exist (run without --summarize-only first)")
        raise typer.Exit(2)
    if not summarize_only:
        try:
            run_experiment(steps, out, progress=lambda msg: err.print(f"fold: {msg}", highlight=False), workers=workers,
                           keep_networks=keep_networks, networks_from=networks_from, ray=ray, only_folds=fold)
        except UnknownFold as exc:
            err.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(2)
        except Exception as exc:  # Ray's own failures (an address, a dead cluster) are one line, not a traceback
            reason = ray_failure(exc)
            if reason is None:
                raise
            err.print(f"[red]error:[/red] {reason}")
            raise typer.Exit(2)
    md = summarize([out / "runs.jsonl"], out / "translation.md", command, "one CPU thread per training process (with --workers N, an ensemble's members train in N such "
                                 "processes: the same networks, less wall time); model seed = CV repeat index (ensemble member m: + m); "
                                 "augmentation/synthetic seed 0 (with member_draws, member m: seed m); "
                                 "both shifted by a model's seed_offset where it has one; "
                                 "epochs, data and beam per model in nl2policy/language/models/config.py",
                   planned=[(d, name, protocol, fold_count(protocol, repeats)) for d, name, protocol, repeats in steps])
    console.print(md.read_text(), markup=False, highlight=False)


def main() -> None:
    app = typer.Typer(add_completion=False)
    app.command()(translation_experiment)
    app(args=normalize_ray_flag(sys.argv[1:]))


if __name__ == "__main__":
    main()
