"""The terminal side shared by every command: the two Rich consoles, the one way a command
fails (``error: ...`` on stderr, exit code 2, no traceback), and the checks that turn bad
arguments into that one line before any work starts.

It never imports ``nl2policy.cli`` (the outermost layer); the area ``commands`` modules and the
CLI import it. Heavy modules are imported inside the helpers that need them, so ``--help`` and a
translation do not pay for them.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import typer
from rich.console import Console
from rich.markup import escape
from typer._click import exceptions as click_errors  # typer 0.29 carries its own click (pinned)
from typer.core import TyperGroup

from nl2policy.errors import UserError
from nl2policy.limits import MAX_SEED, clipped, description_problem, steps_problem, text_problem, trained_steps

if TYPE_CHECKING:
    from rich.progress import Progress

    from nl2policy.app.store import Store

console = Console()
err = Console(stderr=True)
owns_process = False
"""True when the command line is the whole process (``cli.main``), not a test's CliRunner."""


def exit_without_teardown() -> None:
    """End a finished command at once, skipping the interpreter's teardown of torch, a part of a
    cold translation's wall time that the user waits for and that does nothing for them. Only
    when the command is the whole process, everything is written and flushed, and the command
    has nothing left to clean up."""
    if owns_process:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)


def fail(message: str, code: int = 2) -> NoReturn:
    """Print ``error: message`` as one short line on stderr and exit with `code` (2: bad input)."""
    one_line = clipped(" ".join(str(message).split()))
    err.print(f"[bold red]error:[/] {escape(one_line)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


EXPECTED_ERRORS = (UserError, OSError, UnicodeError)
"""What a command may meet that is the user's or the machine's to fix, not a bug: a corpus or
model folder that is missing, a disk that is full or read-only, text that is not UTF-8."""


def _os_reason(exc: OSError) -> str:
    where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
    return f"{exc.strerror or exc}{where}"


class CommandGroup(TyperGroup):
    """The outermost layer of every command: an expected error (EXPECTED_ERRORS) or a usage
    error (a bad option value, an unknown command) ends as one ``error: ...`` line and exit
    code 2, never a traceback or a boxed screen. Bugs still raise, so they are seen."""

    def invoke(self, ctx: typer.Context):
        try:
            return super().invoke(ctx)
        except (click_errors.NoArgsIsHelpError, typer.Exit):
            raise
        except click_errors.UsageError as exc:
            command = f" {exc.ctx.command_path} --help" if exc.ctx is not None else " --help"
            fail(f"{exc.format_message()} (see{command})")
        except EXPECTED_ERRORS as exc:
            if isinstance(exc, BrokenPipeError):
                raise typer.Exit(1)
            fail(_os_reason(exc) if isinstance(exc, OSError) and not isinstance(exc, UserError) else str(exc))


def argv_problem(args: list[str]) -> str | None:
    """Why the command line cannot be read: an argument that is not valid text (Python hands
    invalid UTF-8 over as lone surrogates, which fail wherever they are printed or stored)."""
    for i, arg in enumerate(args):
        problem = text_problem(arg, f"argument {i + 1}")
        if problem:
            return problem + "; pass UTF-8 text"
    return None


def progress_bar(**kwargs) -> "Progress":
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=err, transient=True, **kwargs)


def domain_or_fail(name: str):
    from nl2policy.domains import get_domain

    try:
        return get_domain(name)
    except KeyError as exc:
        fail(str(exc.args[0]))


def tree_or_fail(domain: str, arg: str):
    """A tree from a CLI argument (inline JSON or a file), or exit 2 naming the problem."""
    from nl2policy.trees import TreeError, load_tree_arg

    d = domain_or_fail(domain)
    try:
        return load_tree_arg(arg, d.vocab)
    except TreeError as exc:
        fail(f"bad tree: {exc}")


def seed_or_fail(seed: int, option: str = "--seed") -> int:
    """numpy and gymnasium take seeds in [0, 2^32 - 1]; anything else fails later with a traceback."""
    if not 0 <= seed <= MAX_SEED:
        fail(f"{option} must be a whole number from 0 to {MAX_SEED}, not {seed}")
    return seed


def steps_or_fail(domain: str, steps: int, option: str = "--steps", simulator: str = "fast") -> int:
    """The steps that will really be trained: refuse fewer than one PPO rollout (it would train
    a whole one anyway), and say so when the number is rounded up to whole rollouts."""
    problem = steps_problem(domain, steps, option, simulator)
    if problem:
        fail(problem)
    trained = trained_steps(domain, steps, simulator)
    if trained != steps:
        err.print(f"note: {domain} trains in whole PPO rollouts: {option} {steps} trains {trained} steps", highlight=False)
    return trained


def description_or_fail(text: str) -> str:
    """The same rules as the web API: not empty, not longer than limits.MAX_DESCRIPTION."""
    problem = description_problem(text)
    if problem:
        fail(problem)
    return text


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def out_dir_or_fail(path: Path, option: str = "--out") -> Path:
    """A folder we can create files in (made if missing), checked before any work starts, so
    a long run does not die at its end on an unwritable --out."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        fail(f"{option} {path} is a file, not a folder: choose a folder to write into")
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        fail(f"cannot write into {option} folder {path}: {_reason(exc)}; choose a writable folder")
    return path


def out_file_or_fail(path: Path, option: str = "--out") -> Path:
    """A file path we can write: not a folder, in a folder that exists and takes new files.
    Probed by creating a scratch file beside it, so root, /proc and read-only mounts all count."""
    path = Path(path)
    if path.is_dir():
        fail(f"{option} {path} is a folder: give a file name to write, e.g. {path / 'out.jsonl'}")
    folder = path.parent
    if not folder.is_dir():
        fail(f"cannot write {option} {path}: the folder {folder} does not exist")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
        if path.exists():
            with path.open("a"):
                pass
    except OSError as exc:
        fail(f"cannot write {option} {path}: {_reason(exc)}; choose a writable place")
    return path


def store_or_fail(path: Path) -> "Store":
    """The app's database, or one line naming the file and what to do (never a new empty one
    on top of a damaged file)."""
    from nl2policy.app.store import Store, StoreError

    try:
        return Store(path)
    except StoreError as exc:
        fail(str(exc))


def home_or_fail() -> Path:
    """$NL2POLICY_HOME (or the user data dir), or one line saying it cannot be made."""
    from nl2policy.paths import HomeError, home

    try:
        return home()
    except HomeError as exc:
        fail(str(exc))
