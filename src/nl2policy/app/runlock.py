"""One writer per run folder: the trainer holds an exclusive lock on ``<run>/run.lock`` (with
its PID written inside) for as long as it lives.

An advisory ``flock`` is released by the kernel when its holder dies, kill -9 included, so a
stale lock file never blocks a resume, while a live trainer (an orphan of a killed server, or
a second server on the same data folder) always does.
"""

from __future__ import annotations

import fcntl
import os
import time
from pathlib import Path
from typing import IO, Optional

LOCK_NAME = "run.lock"


class RunLocked(RuntimeError):
    """Another live process is writing the run folder."""

    def __init__(self, folder: Path, pid: Optional[int]) -> None:
        self.folder, self.pid = Path(folder), pid
        who = f"process {pid}" if pid else "another process"
        super().__init__(f"{who} is still writing the run folder {folder}; wait for it to end or stop it first")


def acquire(folder: Path, tries: int = 10) -> IO[str]:
    """Lock `folder` for this process and write our PID; keep the returned file open while
    writing. `tries` rides out a `holder()` probe that holds the lock for an instant."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fh = open(folder / LOCK_NAME, "a+")
    for attempt in range(tries):
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except BlockingIOError:
            if attempt == tries - 1:
                fh.close()
                raise RunLocked(folder, holder(folder)) from None
            time.sleep(0.1)
    fh.seek(0)
    fh.truncate()
    fh.write(f"{os.getpid()}\n")
    fh.flush()
    return fh


def holder(folder: Path) -> Optional[int]:
    """The PID of the live process holding `folder`'s lock (0 if it wrote none yet), or None."""
    path = Path(folder) / LOCK_NAME
    if not path.is_file():
        return None
    with open(path) as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            text = fh.read().strip()
            return int(text) if text.isdigit() else 0
        fcntl.flock(fh, fcntl.LOCK_UN)
    return None
