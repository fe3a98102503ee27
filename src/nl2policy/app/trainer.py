"""The process the app starts for a run: ``python -m nl2policy.app.trainer PARENT_PID FOLDER
-- ARGS`` runs ``nl2policy ARGS`` (the ``optimize`` command) after two guards:

* it dies with the server: the kernel sends it SIGTERM when its parent goes
  (``PR_SET_PDEATHSIG`` on Linux), and a watchdog thread does the same wherever that is missing,
  so a kill -9 of the server leaves no orphan training on;
* it holds the run folder's lock (``runlock``) while it lives, so a resume after a restart can
  never start a second writer in the same folder. A folder locked by someone else: exit code 3.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from pathlib import Path

from nl2policy.app.runlock import RunLocked, acquire

PR_SET_PDEATHSIG = 1
LOCKED_EXIT = 3


def die_with_parent(parent: int, poll_seconds: float = 0.5) -> None:
    """SIGTERM ourselves when `parent` is no longer our parent (it died; we were re-parented)."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        except (OSError, AttributeError):
            pass  # the watchdog below still covers it
    if os.getppid() != parent:  # the parent died before prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_seconds)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[2] != "--":
        print("usage: python -m nl2policy.app.trainer PARENT_PID FOLDER -- NL2POLICY_ARGS...", file=sys.stderr)
        return 2
    die_with_parent(int(argv[0]))
    try:
        lock = acquire(Path(argv[1]))
    except RunLocked as exc:
        print(f"error: {exc}", file=sys.stderr)
        return LOCKED_EXIT
    import typer

    from nl2policy.policy.commands import optimize

    # The one command a run executes, as the CLI registers it, without importing the CLI.
    app = typer.Typer(add_completion=False)
    app.callback()(lambda: None)  # a group, so the command is named on the command line as in the CLI
    app.command("optimize")(optimize)
    try:
        app(argv[3:], prog_name="nl2policy")
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        lock.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
