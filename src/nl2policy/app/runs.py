"""Optimization runs in the background, one at a time, each in its own process.

A run is the ``nl2policy optimize`` command itself, started as a child process with its
output folder under the app's data directory: the app shows exactly what the CLI makes,
the CLI's checkpoints make a run resumable, and a crash in training cannot take the server
down. The queue lives in SQLite, so a restart loses nothing: finished runs stay finished,
and runs that were going are marked interrupted, ready to resume.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Optional

from nl2policy.app.store import Store


class RunManager:
    def __init__(self, store: Store, max_parallel: int = 1) -> None:
        self.store = store
        self.max_parallel = max_parallel
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._active: dict[str, subprocess.Popen] = {}
        self._watchers: list[threading.Thread] = []
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name="run-manager", daemon=True)

    def start(self) -> None:
        self.store.mark_unfinished_interrupted()
        self._thread.start()

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
        self.store.set_run_status(run_id, "queued")
        with self._wake:
            self._wake.notify_all()

    def _loop(self) -> None:
        while True:
            with self._wake:
                while not self._stopping and (len(self._active) >= self.max_parallel or not self._next_queued()):
                    self._wake.wait(timeout=1.0)
                if self._stopping:
                    return
                run = self._next_queued()
                self.store.set_run_status(run["id"], "running")
                proc = self._launch(run)
                self._active[run["id"]] = proc
            watcher = threading.Thread(target=self._watch, args=(run, proc), daemon=True)
            self._watchers = [w for w in self._watchers if w.is_alive()] + [watcher]
            watcher.start()

    def _next_queued(self) -> Optional[dict]:
        queued = self.store.list_runs(status="queued", limit=1)
        return queued[0] if queued else None

    def _launch(self, run: dict) -> subprocess.Popen:
        out = Path(run["out_dir"])
        out.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "nl2policy.cli", "optimize", "--domain", run["domain"],
               "--tree", json.dumps(run["tree"]), "--steps", str(run["steps"]), "--seed", str(run["seed"]),
               "--out", str(out)]
        log = open(out / "log.txt", "ab")
        return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)

    def _watch(self, run: dict, proc: subprocess.Popen) -> None:
        code = proc.wait()
        with self._wake:
            self._active.pop(run["id"], None)
            stopping = self._stopping
            self._wake.notify_all()
        out = Path(run["out_dir"])
        summary_path = out / "summary.json"
        if code == 0 and summary_path.is_file():
            self.store.set_run_status(run["id"], "finished", summary=json.loads(summary_path.read_text()))
        elif stopping:
            self.store.set_run_status(run["id"], "interrupted", error="the server stopped; resume to continue")
        else:
            tail = (out / "log.txt").read_text(errors="replace")[-800:] if (out / "log.txt").exists() else ""
            self.store.set_run_status(run["id"], "failed", error=f"exit code {code}: {tail}")

    def active(self) -> list[str]:
        with self._lock:
            return list(self._active)


def read_curve(out_dir: Path, domain: str) -> list[dict]:
    """The learning curve so far as [{"step", "rolling_mean"}].

    A finished run has curve.csv; a running one has only its latest checkpoint's episode log
    (state.json, rewritten after every chunk of training), from which the same rolling mean
    is computed.
    """
    from nl2policy.policy.optimize import STATE, WINDOW, rolling_mean

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
    means = rolling_mean([r for _, r in episodes], WINDOW[domain])
    return [{"step": float(s), "rolling_mean": float(m)} for (s, _), m in zip(episodes, means)]
