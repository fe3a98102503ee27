"""The ``nl2policy`` command line. Each command is a thin shell over a library function.

The shared terminal helpers (consoles, ``fail``, argument checks) live in ``nl2policy.console``
and are re-exported here for the area ``commands`` modules. Heavy libraries are imported inside
the commands that use them, so ``--help`` and ``translate`` start quickly.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

from nl2policy.console import (CommandGroup, argv_problem, console, description_or_fail, domain_or_fail, err, fail,
                               out_dir_or_fail, progress_bar, seed_or_fail, steps_or_fail, tree_or_fail)
from nl2policy.domains import DOMAINS
from nl2policy.limits import MAX_CLI_STEPS, MAX_EPISODES

app = typer.Typer(cls=CommandGroup, add_completion=False, no_args_is_help=True,
                  help="Plain-English robot policies as readable, trainable decision trees.")

__all__ = ["app", "console", "err", "fail", "progress_bar", "domain_or_fail", "tree_or_fail", "main"]


@app.command()
def evaluate(
    domain: str = typer.Option(..., help=f"One of: {', '.join(DOMAINS)}"),
    tree: str = typer.Option(..., help="A tree as inline JSON or a path to a JSON file"),
    episodes: int = typer.Option(20, min=1, max=MAX_EPISODES),
    seed: int = typer.Option(0),
) -> None:
    """Run a tree as a policy; print {"mean_return", "stderr", "episodes"} as JSON."""
    from nl2policy.policy.rollout import evaluate as run_eval, tree_policy

    seed_or_fail(seed)
    parsed = tree_or_fail(domain, tree)
    with progress_bar() as bar:
        task = bar.add_task(f"{domain} episodes", total=episodes)
        result = run_eval(domain, tree_policy(domain, parsed), episodes, seed,
                          progress=lambda n: bar.update(task, completed=n))
    print(json.dumps(result.summary()))


@app.command()
def compare(episodes: int = typer.Option(10, min=1, max=MAX_EPISODES), seed: int = typer.Option(0)) -> None:
    """The most common corpus trees against the random policy (and taxi's optimum), per domain."""
    from nl2policy.compare import run_compare

    seed_or_fail(seed)
    run_compare(console, episodes, seed)


@app.command()
def run(
    text: Optional[str] = typer.Argument(None, help="What the robot should do, in plain English (default: an example)"),
    domain: str = typer.Option("taxi", help=f"One of: {', '.join(DOMAINS)}"),
    steps: int = typer.Option(10_000, max=MAX_CLI_STEPS, help="PPO env steps (whole rollouts: rounded up to a multiple of 512 for taxi, 4,096 for highway on its twin)"),
    seed: int = typer.Option(0),
    out: Path = typer.Option(Path("runs/main"), help="Output folder for trees, curve and summary"),
) -> None:
    """The main job: translate a description, show the tree, optimize it with PPO, show it again."""
    from nl2policy.pipeline import run_pipeline

    d = domain_or_fail(domain)
    text = description_or_fail(d.example if text is None else text)
    seed_or_fail(seed)
    steps_or_fail(domain, steps)
    run_pipeline(console, err, domain, text, steps, seed, out_dir_or_fail(out / domain))
    console.print("\nTo describe, edit and optimize policies in the browser: [bold]make serve[/] "
                  "(or `.venv/bin/nl2policy serve`), then open http://127.0.0.1:8000/")


def _register_area_commands() -> None:
    """Each area (policy, language, app) adds its own commands from its ``commands`` module."""
    import importlib

    for area in ("policy", "language", "app"):
        try:
            module = importlib.import_module(f"nl2policy.{area}.commands")
        except ModuleNotFoundError as exc:
            if exc.name not in (f"nl2policy.{area}", f"nl2policy.{area}.commands"):
                raise
            continue
        module.register(app)


_register_area_commands()


def main() -> None:  # pragma: no cover - console entry
    """The ``nl2policy`` executable: the command line owns the process (see
    ``console.exit_without_teardown``)."""
    from nl2policy import console as terminal

    terminal.owns_process = True

    from nl2policy.domains import PROBLEMS

    problem = argv_problem(sys.argv[1:]) or "; ".join(PROBLEMS)
    if problem:
        err.print(f"[bold red]error:[/] {problem}", highlight=False, soft_wrap=True)
        sys.exit(2)
    app(args=sys.argv[1:])


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
