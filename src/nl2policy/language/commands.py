"""CLI commands of the language area: train-translator and translate. (The translation
experiment, a lab harness, is `python -m experiments.translation`.)"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from nl2policy.limits import MAX_COUNT


def register(app: typer.Typer) -> None:
    app.command("train-translator")(train_translator)
    app.command("translate")(translate_cmd)


def train_translator(
    domain: str = typer.Option(..., help="taxi or highway"),
    model: Optional[str] = typer.Option(None, help="Model name (default: the best model)"),
    seed: int = typer.Option(0),
    out: Optional[Path] = typer.Option(None, help="Folder to save into (default: $NL2POLICY_HOME/models)"),
    workers: Optional[int] = typer.Option(None, min=1, max=MAX_COUNT, help="Processes training ensemble members side by side "
                                          "(default: one per CPU core); the trained networks do not depend on it"),
) -> None:
    """Train a translator on the whole shared corpus and save it as the domain's model (resumes
    from its checkpoint if a run was interrupted)."""
    from nl2policy.console import domain_or_fail, err, fail, out_dir_or_fail, progress_bar
    from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
    from nl2policy.language.shipping import train_default

    domain_or_fail(domain)
    if out is not None:
        out_dir_or_fail(out)
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
    json_out: bool = typer.Option(False, "--json", help='Print {"tree", "confidence", "warnings", "questions"} as JSON'),
    jsonl: Optional[Path] = typer.Option(None, "--jsonl", help="File with one JSON object per line holding a description"),
    model: Optional[str] = typer.Option(None, help="Model name (default: the best model)"),
    answer: Optional[list[str]] = typer.Option(None, "--answer", help='Your answer to a question it asked, as JSON: '
                                               '\'{"situation": {...}, "do": "ACTION"}\' (repeatable, in the order asked)'),
    interactive: bool = typer.Option(False, "--interactive", help="Answer its questions on the terminal (Enter skips), "
                                                                 "then print the final tree"),
    max_questions: int = typer.Option(3, min=0, max=MAX_COUNT, help="Questions it may ask about one description"),
) -> None:
    """Translate a description into a policy tree with its confidence; where it is unsure, it asks
    what the robot should do in a situation, and each answer holds the tree to it."""
    from nl2policy.console import console, description_or_fail, domain_or_fail, err, exit_without_teardown, fail
    from nl2policy.language.models.config import DEFAULT_MODEL, MODELS

    d = domain_or_fail(domain)
    name = model or DEFAULT_MODEL
    if name not in MODELS:
        fail(f"unknown model {name!r}; known: {', '.join(MODELS)}")
    answers = [_answer_arg(a, i) for i, a in enumerate(answer or [], 1)]
    if jsonl is not None and (answers or interactive):
        fail("--answer and --interactive are for one description, not --jsonl")
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

    from nl2policy.language.clarify import BadAnswer, NoTreeFits
    from nl2policy.language.translate import EmptyDescription, translate
    from nl2policy.trees import to_text

    # One torch thread, as the server and the experiments translate: a single short text gains
    # nothing from more, and starting torch's thread pool for it made the first pass of a cold
    # translation many times slower on a busy 2-core machine (the last phase that
    # benchmarks/cold_translate.py prints).
    torch.set_num_threads(1)
    from nl2policy.paths import HomeError

    def run(given: list) -> "object":
        try:
            return translate(domain, text, name, answers=given, max_questions=max_questions)
        except (EmptyDescription, HomeError, BadAnswer, NoTreeFits) as exc:  # HomeError: no model, and nowhere to train one
            fail(str(exc))

    result = run(answers)
    if interactive:
        result = _ask_on_terminal(run, answers, result, d)
    if json_out:
        print(json.dumps(result.to_json()))
    else:
        console.print(to_text(result.tree, d.vocab), highlight=False)
        console.print(f"confidence: {result.confidence:.2f}", highlight=False)
        for w in result.warnings:
            err.print(f"[yellow]warning:[/] {w}", highlight=False)
        for q in result.questions:
            err.print(f"question: {q.text} Answer with --answer '{json.dumps({'situation': dict(q.situation), 'do': 'ACTION'})}', "
                      f"ACTION one of {', '.join(a for a, _ in q.choices)}", highlight=False, soft_wrap=True)
    exit_without_teardown()


def _answer_arg(raw: str, i: int):
    """One --answer value as JSON (its contents are checked by the translator)."""
    from nl2policy.console import fail

    try:
        return json.loads(raw)
    except json.JSONDecodeError as exc:
        fail(f"--answer {i} is not JSON ({exc.msg}); write '{{\"situation\": {{...}}, \"do\": \"ACTION\"}}'")


def _ask_on_terminal(run, answers: list, result, d):
    """Ask each question on the terminal with numbered choices until none is asked or the user
    presses Enter; the tree after each answer is shown."""
    from rich.prompt import Prompt

    from nl2policy.console import err
    from nl2policy.trees import to_text

    while result.questions:
        q = result.questions[0]
        err.print(f"\n[bold]{q.text}[/]", highlight=False)
        for n, (_, words) in enumerate(q.choices, 1):
            err.print(f"  {n}. {words}", highlight=False)
        choice = Prompt.ask("your choice (Enter skips)", choices=[str(n) for n in range(1, len(q.choices) + 1)] + [""],
                            default="", show_choices=False, console=err)
        if not choice:
            break
        answers.append({"situation": dict(q.situation), "do": q.choices[int(choice) - 1][0]})
        result = run(answers)
        err.print(to_text(result.tree, d.vocab), highlight=False)
    return result


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
