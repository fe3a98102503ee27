"""The product's up-front checks (`nl2policy.console`'s `*_or_fail`) for the lab's argparse
commands. A folder that cannot be written is said in one line before an hour of training or
translating, not as a traceback at its end. The product's checks print `error: ...` and raise
`typer.Exit`, which only a Typer app turns into an exit code; here it becomes `SystemExit`."""

from __future__ import annotations

from typing import Callable, TypeVar

import typer

T = TypeVar("T")


def before_work(check: Callable[..., T], *args: object) -> T:
    """`check(*args)`, or exit with its code (2) after it has said what is wrong."""
    try:
        return check(*args)
    except typer.Exit as exc:
        raise SystemExit(exc.exit_code) from None
