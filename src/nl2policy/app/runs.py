"""Optimization runs in the background, one at a time, each in its own process.

A run is the ``nl2policy optimize`` command itself, started as a child process with its
output folder under the app's data directory: the app shows exactly what the CLI makes,
the CLI's checkpoints make a run resumable, and a crash in training cannot take the server
down. The queue lives in SQLite, so a restart loses nothing: finished runs stay finished,
and runs that were going are marked interrupted, ready to resume.

The child runs under ``nl2policy.app.trainer``: it dies with the server and holds its folder's
lock, so a restart never meets an orphan still writing a folder it would resume. On start, the
database is reconciled with the folders: a run whose summary is on disk finished (perhaps while
orphaned by an older version) and is recorded so.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import re
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Optional

from nl2policy.app.runlock import holder
from nl2policy.app.store import Store
from nl2policy.app.trainer import LOCKED_EXIT

log = logging.getLogger("nl2policy.runs")
STORE_FAULTS = (sqlite3.Error, OSError)
"""What the database can raise while it is locked by another process, damaged or on a failing
disk: the run manager outlives every one of them."""
RETRY_MAX_S = 5.0
"""The longest wait between two tries at a store that failed (the waits double from 0.25 s)."""


class RunManager:
    def __init__(self, store: Store, max_parallel: int = 1) -> None:
        self.store = store
        self.max_parallel = max_parallel
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._active: dict[str, subprocess.Popen] = {}
        self._cancelling: set[str] = set()
        # runs submitted to this manager: the reconcile, which may run after the first requests
        # on a busy machine, must not mark them as left over from an earlier server
        self._submitted: set[str] = set()
        self._watchers: list[threading.Thread] = []
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name="run-manager", daemon=True)

    def start(self) -> None:
        self._thread.start()  # it reconciles first, retrying while the store fails

    def reconcile(self) -> None:
        """After a restart no run of an earlier server is going: record what the folders say
        happened. Runs submitted to this manager meanwhile are left alone (checked under the lock
        `submit` takes, so a submission can never be overwritten as "interrupted")."""
        for status in ("running", "queued"):
            for run in self.store.list_runs(status=status, limit=10_000):
                with self._lock:
                    current = self.store.get_run(run["id"])  # as it is now, not as listed
                    if run["id"] not in self._submitted and current is not None and current["status"] == status:
                        self._reconcile_one(current)

    def _reconcile_one(self, run: dict) -> None:
        out = Path(run["out_dir"])
        summary = _read_summary(out)
        pid = holder(out)
        if summary is not None and pid is None:
            self.store.set_run_status(run["id"], "finished", summary=summary)
        elif pid is not None:
            self.store.set_run_status(run["id"], "interrupted", error=f"process {pid} from an earlier server "
                                      "is still writing this run; it can be resumed once that process ends")
        else:
            self.store.set_run_status(run["id"], "interrupted", error="the server stopped; resume to continue")

    def stop(self) -> None:
        with self._wake:
            self._stopping = True
            procs = list(self._active.values())
            self._wake.notify_all()
        for proc in procs:  # the run's checkpoint lets it resume after the restart
            proc.terminate()
        self._thread.join(timeout=10)
        for watcher in self._watchers:  # record "interrupted" now: a late write would hit a resumed run
            watcher.join(timeout=10)

    def submit(self, run_id: str) -> None:
        """Queue a run (new, or interrupted and being resumed)."""
        with self._wake:
            self._submitted.add(run_id)
            self.store.set_run_status(run_id, "queued")
            self._wake.notify_all()

    def cancel(self, run_id: str) -> bool:
        """Stop a queued or running run (its checkpoint stays, so it can be resumed); False when
        it was neither."""
        with self._wake:
            run = self.store.get_run(run_id)
            if run is None or run["status"] not in ("queued", "running"):
                return False
            proc = self._active.get(run_id)
            if proc is None:
                self.store.set_run_status(run_id, "cancelled", error="cancelled before it started")
                return True
            self._cancelling.add(run_id)
        proc.terminate()
        return True

    def _loop(self) -> None:
        """Reconcile, then start queued runs as slots free up. A store fault (a lock held past
        SQLite's timeout, a damaged file, a failing disk) is logged and retried with a growing
        wait, so queued runs start as soon as the store is healthy again."""
        self._retrying(self.reconcile)
        while not self._stopping:
            started = self._retrying(self._start_next)
            if started is not None:
                run, proc, log_start = started
                watcher = threading.Thread(target=self._watch, args=(run, proc, log_start), daemon=True)
                self._watchers = [w for w in self._watchers if w.is_alive()] + [watcher]
                watcher.start()

    def _retrying(self, step):
        """`step()`, tried again after every store fault until it succeeds or the manager stops
        (then None)."""
        wait = 0.25
        while not self._stopping:
            try:
                return step()
            except STORE_FAULTS as exc:
                log.warning("run manager: the database failed (%s); retrying in %.2g s", exc, wait)
                with self._wake:
                    self._wake.wait(timeout=wait)
                wait = min(2 * wait, RETRY_MAX_S)
        return None

    def _start_next(self) -> Optional[tuple[dict, subprocess.Popen, int]]:
        """Wait for a free slot and a queued run, mark it running and launch it; None when
        stopping."""
        with self._wake:
            while not self._stopping and (len(self._active) >= self.max_parallel or not self._next_queued()):
                self._wake.wait(timeout=1.0)
            if self._stopping:
                return None
            run = self._next_queued()
            self.store.set_run_status(run["id"], "running")
            try:
                proc, log_start = self._launch(run)
            except OSError as exc:  # its folder cannot be written: this run fails, the others go on
                self.store.set_run_status(run["id"], "failed", error=f"could not start the training process: {exc}")
                return None
            self._active[run["id"]] = proc
            return run, proc, log_start

    def _next_queued(self) -> Optional[dict]:
        queued = self.store.list_runs(status="queued", limit=1)
        return queued[0] if queued else None

    def _launch(self, run: dict) -> tuple[subprocess.Popen, int]:
        """Start the run's trainer; also return where this attempt's output starts in log.txt
        (a resumed run appends to it), so a failure is explained by this attempt's lines."""
        out = Path(run["out_dir"])
        out.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "nl2policy.app.trainer", str(os.getpid()), str(out), "--",
               "optimize", "--domain", run["domain"],
               "--tree", json.dumps(run["tree"]), "--steps", str(run["steps"]), "--seed", str(run["seed"]),
               "--out", str(out)]
        with open(out / "log.txt", "ab") as log:
            start = log.tell()
            return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL), start

    def _watch(self, run: dict, proc: subprocess.Popen, log_start: int = 0) -> None:
        code = proc.wait()
        with self._wake:
            self._active.pop(run["id"], None)
            stopping = self._stopping
            cancelled = run["id"] in self._cancelling
            self._cancelling.discard(run["id"])
            self._wake.notify_all()
        out = Path(run["out_dir"])
        summary = _read_summary(out)
        if code == 0 and summary is not None:
            status, fields = "finished", {"summary": summary}
        elif cancelled:
            status, fields = "cancelled", {"error": "cancelled; resume to continue from its last checkpoint"}
        elif stopping:
            status, fields = "interrupted", {"error": "the server stopped; resume to continue"}
        elif code == LOCKED_EXIT:
            status, fields = "interrupted", {"error": failure_reason(out, code, log_start)}
        else:
            status, fields = "failed", {"error": failure_reason(out, code, log_start)}
        # a store fault must not leave the run "running" for ever; if the server stops first,
        # the next start's reconcile reads the outcome from the folder
        self._retrying(lambda: self.store.set_run_status(run["id"], status, **fields))

    def active(self) -> list[str]:
        with self._lock:
            return list(self._active)


def _read_summary(out: Path) -> Optional[dict]:
    """summary.json, written last by a run that completed; None if absent or unreadable."""
    try:
        return json.loads((Path(out) / "summary.json").read_text())
    except (OSError, json.JSONDecodeError):
        return None


def failure_reason(out: Path, code: int, log_start: int = 0) -> str:
    """One readable line on why a run failed: the command's own ``error:`` line, else the
    last exception line of its log (from `log_start`: this attempt), else the exit code. The
    full log stays in log.txt."""
    try:
        with open(Path(out) / "log.txt", "rb") as fh:
            fh.seek(log_start)
            text = fh.read().decode(errors="replace")
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    except OSError:
        lines = []
    said = [ln for ln in lines if ln.lower().startswith("error:")]
    raised = [ln for ln in lines if re.match(r"^[A-Za-z_.]*(Error|Exception|Interrupt)\b", ln)]
    if said:
        reason = said[-1][len("error:"):].strip()
    elif raised:
        reason = raised[-1]
    elif code < 0:
        reason = f"the training process was stopped by signal {-code}"
    else:
        reason = f"the training process exited with code {code}"
    return f"{reason[:300]} (full log: {Path(out) / 'log.txt'})"


def read_curve(out_dir: Path, domain: str) -> list[dict]:
    """The learning curve so far as [{"step", "rolling_mean"}].

    A finished run has curve.csv; a running one has only its latest checkpoint's episode log
    (state.json, rewritten after every chunk of training), from which the same rolling mean
    is computed.
    """
    from nl2policy.domains import get_domain
    from nl2policy.policy.optimize import STATE, rolling_mean

    out_dir = Path(out_dir)
    path = out_dir / "curve.csv"
    if path.is_file():
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
        if len(rows) > 1:
            header = rows[0]
            step_col, mean_col = header.index("step"), next(i for i, h in enumerate(header) if h.startswith("rolling_mean"))
            return [{"step": float(r[step_col]), "rolling_mean": float(r[mean_col])} for r in rows[1:] if len(r) == len(header)]
    state = out_dir / STATE
    if not state.is_file():
        return []
    try:
        episodes = json.loads(state.read_text())["episodes"]
    except (json.JSONDecodeError, KeyError):
        return []  # caught mid-write; the next poll will read it
    means = rolling_mean([r for _, r in episodes], get_domain(domain).knobs.rolling_window)
    return [{"step": float(s), "rolling_mean": float(m)} for (s, _), m in zip(episodes, means)]
