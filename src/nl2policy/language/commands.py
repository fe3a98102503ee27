"""CLI commands of the language area: train-translator, translate, translation-experiment."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer


def register(app: typer.Typer) -> None:
    app.command("train-translator")(train_translator)
    app.command("translate")(translate_cmd)
    app.command("translation-experiment")(translation_experiment)


def train_translator(
    domain: str = typer.Option(..., help="taxi or highway"),
    model: Optional[str] = typer.Option(None, help="Model name (default: the best model)"),
    seed: int = typer.Option(0),
    out: Optional[Path] = typer.Option(None, help="Folder to save into (default: $NL2POLICY_HOME/models)"),
    workers: Optional[int] = typer.Option(None, min=1, help="Processes training ensemble members side by side "
                                          "(default: one per CPU core); the trained networks do not depend on it"),
) -> None:
    """Train a translator on the whole shared corpus and save it as the domain's model (resumes
    from its checkpoint if a run was interrupted)."""
    from nl2policy.console import domain_or_fail, err, fail, progress_bar
    from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
    from nl2policy.language.translate import train_default

    domain_or_fail(domain)
    name = model or DEFAULT_MODEL
    if name not in MODELS:
        fail(f"unknown model {name!r}; known: {', '.join(MODELS)}")
    with progress_bar() as bar:
        task = bar.add_task(f"training {name} for {domain}", total=None)
        path = train_default(domain, name, seed, progress=lambda done, total: bar.update(task, completed=done, total=total), out=out,
                             workers=workers)
    err.print(f"saved {path}")


def translate_cmd(
    text: Optional[str] = typer.Argument(None, help="The description to translate"),
    domain: str = typer.Option(..., help="taxi or highway"),
    json_out: bool = typer.Option(False, "--json", help='Print {"tree", "confidence", "warnings"} as JSON'),
    jsonl: Optional[Path] = typer.Option(None, "--jsonl", help="File with one JSON object per line holding a description"),
    model: Optional[str] = typer.Option(None, help="Model name (default: the best model)"),
) -> None:
    """Translate a description into a policy tree with its confidence."""
    from nl2policy.console import console, description_or_fail, domain_or_fail, err, exit_without_teardown, fail
    from nl2policy.language.models.config import DEFAULT_MODEL, MODELS

    d = domain_or_fail(domain)
    name = model or DEFAULT_MODEL
    if name not in MODELS:
        fail(f"unknown model {name!r}; known: {', '.join(MODELS)}")
    if jsonl is not None:
        if text is not None:
            fail("give either a TEXT argument or --jsonl FILE, not both")
        if not jsonl.is_file():
            fail(f"no such file: {jsonl}")
        try:
            lines = jsonl.read_text(encoding="utf-8").splitlines()
        except UnicodeDecodeError:
            fail(f"--jsonl {jsonl} is not a UTF-8 text file (one JSON object per line)")
        except OSError as exc:
            fail(f"cannot read --jsonl {jsonl}: {exc.strerror or exc}")
        from nl2policy.language.translate import get_model
        from nl2policy.paths import HomeError

        try:
            get_model(domain, name)
        except HomeError as exc:  # no model, and nowhere to train one
            fail(str(exc))
        for lineno, line in enumerate(lines, 1):
            print(json.dumps(_jsonl_line(domain, name, line, lineno)), flush=True)
        return
    if text is None:
        fail("give a description to translate (or --jsonl FILE)")
    if text.strip():  # an empty one gets the translator's own message below
        description_or_fail(text)
    import torch

    from nl2policy.language.translate import EmptyDescription, translate
    from nl2policy.trees import to_text

    # One torch thread, as the server and the experiments translate: a single short text gains
    # nothing from more, and starting torch's thread pool for it made the first pass of a cold
    # translation many times slower on a busy 2-core machine (the last phase that
    # benchmarks/cold_translate.py prints).
    torch.set_num_threads(1)
    from nl2policy.paths import HomeError

    try:
        result = translate(domain, text, name)
    except (EmptyDescription, HomeError) as exc:  # HomeError: no model, and nowhere to train one
        fail(str(exc))
    if json_out:
        print(json.dumps(result.to_json()))
    else:
        console.print(to_text(result.tree, d.vocab), highlight=False)
        console.print(f"confidence: {result.confidence:.2f}", highlight=False)
        for w in result.warnings:
            err.print(f"[yellow]warning:[/] {w}", highlight=False)
    exit_without_teardown()


def _jsonl_line(domain: str, name: str, line: str, lineno: int) -> dict:
    """One output object per input line: the translation, or {"error": why}."""
    from nl2policy.language.translate import EmptyDescription, translate
    from nl2policy.limits import MAX_DESCRIPTION

    try:
        row = json.loads(line)
    except json.JSONDecodeError as exc:
        return {"error": f"line {lineno}: not valid JSON ({exc.msg})"}
    if not isinstance(row, dict) or "description" not in row:
        return {"error": f"line {lineno}: no 'description' field"}
    if not isinstance(row["description"], str):
        return {"error": f"line {lineno}: 'description' must be a string"}
    if len(row["description"]) > MAX_DESCRIPTION:
        return {"error": f"line {lineno}: the description is {len(row['description']):,} characters long; "
                         f"the limit is {MAX_DESCRIPTION:,}"}
    try:
        return translate(domain, row["description"], name).to_json()
    except EmptyDescription as exc:
        return {"error": f"line {lineno}: {exc}"}


def parse_plan(plan: str, domains: list[str], default_model: str) -> list[tuple[str, str, str, int]]:
    """'model:protocols;...' -> (domain, model, protocol, repeats) steps, in plan order. A model
    prefixed with 'DOMAIN/' runs for that domain only (a probe of one domain must not be listed as
    not run in the others); protocols are cvR (R repeats of 5-fold CV), treesR (R repeats of
    5-fold leave-trees-out on both corpus rounds), writers and new (each round-2 writer held out
    with every policy they describe)."""
    from nl2policy.language.models.config import MODELS

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
            if p in ("writers", "new"):
                protocol, repeats = p, 1
            elif p.startswith("cv") and (p[2:] or "1").isdigit():
                protocol, repeats = "cv", int(p[2:] or 1)
            elif p.startswith("trees") and (p[5:] or "1").isdigit():
                protocol, repeats = "trees", int(p[5:] or 1)
            else:
                raise ValueError(f"plan part {part!r}: protocol {p!r} is not cvR, treesR, writers or new")
            steps += [(d, name, protocol, repeats) for d in domains if not only or d == only]
    return steps


DEFAULT_PLAN = "best:cv1,writers;single:cv1,writers;ablation:cv1,writers;seq2seq:cv1;seq2tree:cv1;han2tree:cv1"


def translation_experiment(
    domain: list[str] = typer.Option(["taxi", "highway"], help="Domains"),
    plan: str = typer.Option(DEFAULT_PLAN, help="model:protocols;... with cvR = R repeats of 5-fold CV, writers = leave-writers-out; "
                                               "'best' = the default model (an ensemble of four), 'single' = one of its "
                                               "networks, 'ablation' = one network without synthetic data; "
                                               "DOMAIN/model runs for that domain only"),
    out: Path = typer.Option(Path("results/translation"), help="Folder for runs.jsonl, translation.md/.json/.png"),
    summarize_only: bool = typer.Option(False, help="Only rewrite the tables from the folds already in runs.jsonl"),
    workers: int = typer.Option(1, min=1, help="Processes training an ensemble's members side by side (one thread "
                                               "each): same results, less wall time on a machine with as many cores"),
    keep_networks: Optional[Path] = typer.Option(None, help="Also save each fold's networks in this folder, to study "
                                                            "decoding choices on them without retraining"),
    networks_from: Optional[Path] = typer.Option(None, help="A --keep-networks folder: a fold whose networks are there "
                                                           "(same fold, a model that trains the same networks) decodes "
                                                           "them instead of training"),
) -> None:
    """Cross-validation and leave-writers-out accuracy of every translator (resumable)."""
    import torch

    from nl2policy.console import console, domain_or_fail, err
    from nl2policy.language.evaluate import fold_count, run_experiment
    from nl2policy.language.summary import summarize
    from nl2policy.language.models.config import DEFAULT_MODEL

    torch.set_num_threads(1)
    for d in domain:
        domain_or_fail(d)
    try:
        steps = parse_plan(plan, domain, DEFAULT_MODEL)
    except ValueError as exc:
        err.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2)
    # run in plan order (most important first): the experiment resumes, so what finished is kept
    command = "nl2policy translation-experiment " + " ".join(f"--domain {d}" for d in domain) + f" --plan '{plan}' --out {out}"
    if summarize_only and not (out / "runs.jsonl").is_file():
        err.print(f"[red]error:[/red] no folds to summarise: {out / 'runs.jsonl'} does not exist (run without --summarize-only first)")
        raise typer.Exit(2)
    if not summarize_only:
        run_experiment(steps, out, progress=lambda msg: err.print(f"fold: {msg}", highlight=False), workers=workers,
                       keep_networks=keep_networks, networks_from=networks_from)
    md = summarize(out, command, "one CPU thread per training process (with --workers N, an ensemble's members train in N such "
                                 "processes: the same networks, less wall time); model seed = CV repeat index (ensemble member m: + m); "
                                 "augmentation/synthetic seed 0 (with member_draws, member m: seed m); "
                                 "both shifted by a model's seed_offset where it has one; "
                                 "epochs, data and beam per model in nl2policy/language/models/config.py",
                   planned=[(d, name, protocol, fold_count(protocol, repeats)) for d, name, protocol, repeats in steps])
    console.print(md.read_text())
