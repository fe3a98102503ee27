"""Regression tests for orphaned trainers (issue 29): a run's trainer dies with the server,
holds its folder's lock while it lives, and a restart records what the folder says happened."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import pytest
from fastapi.testclient import TestClient

from nl2policy.app.runlock import acquire, holder
from nl2policy.app.server import create_app
from nl2policy.app.store import Store
from nl2policy.app.trainer import LOCKED_EXIT

pytestmark = pytest.mark.slow

TREE = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def call(url: str, method: str = "GET", body: dict | None = None) -> dict:
    req = urllib.request.Request(url, method=method, data=None if body is None else json.dumps(body).encode(),
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as res:
        return json.loads(res.read())


def wait_until(predicate, timeout: float, what: str):
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout}s waiting for {what}")


def test_trainer_dies_when_the_server_is_killed(tmp_path):
    port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "nl2policy.cli", "serve", "--port", str(port), "--data-dir", str(tmp_path),
                               "--results", str(tmp_path / "results")], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        url = f"http://127.0.0.1:{port}"

        def up():
            try:
                return call(url + "/api/domains")
            except OSError:
                return None

        wait_until(up, 60, "the server to start")
        run = call(url + "/api/runs", "POST", {"domain": "taxi", "tree": TREE, "steps": 50_000})
        folder = tmp_path / "runs" / run["id"]
        pid = wait_until(lambda: holder(folder), 60, "the trainer to lock its folder")
        assert pid != server.pid
        server.send_signal(signal.SIGKILL)
        server.wait(timeout=10)
        # the kernel releases the lock when the trainer exits; an orphan would keep it for minutes
        wait_until(lambda: holder(folder) is None, 20, f"trainer {pid} to die with its server")
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
        orphan = holder(tmp_path / "runs" / run["id"]) if "run" in locals() else None
        if orphan:  # the test failed: do not leave a trainer behind
            os.kill(orphan, signal.SIGKILL)


def test_a_locked_folder_gets_no_second_trainer(tmp_path):
    folder = tmp_path / "run"
    lock = acquire(folder)
    try:
        assert holder(folder) == os.getpid()
        proc = subprocess.run([sys.executable, "-m", "nl2policy.app.trainer", str(os.getpid()), str(folder), "--",
                               "optimize", "--domain", "taxi", "--tree", json.dumps(TREE), "--steps", "512",
                               "--out", str(folder)], capture_output=True, text=True, timeout=120)
        assert proc.returncode == LOCKED_EXIT
        assert f"process {os.getpid()} is still writing" in proc.stderr
        assert not (folder / "summary.json").exists()
    finally:
        lock.close()
    assert holder(folder) is None


def test_resume_is_refused_while_another_process_writes_the_folder(tmp_path):
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=None, max_parallel_runs=0)
    with TestClient(app, base_url="http://127.0.0.1") as client:
        run_id = client.post("/api/runs", json={"domain": "taxi", "tree": TREE, "steps": 512}).json()["id"]
        client.post(f"/api/runs/{run_id}/cancel")
        lock = acquire(tmp_path / "runs" / run_id)
        try:
            r = client.post(f"/api/runs/{run_id}/resume")
            assert r.status_code == 409 and f"process {os.getpid()}" in r.json()["detail"]
            assert client.delete(f"/api/runs/{run_id}").status_code == 409
        finally:
            lock.close()
        assert client.post(f"/api/runs/{run_id}/resume").json()["status"] == "queued"


def test_restart_marks_a_run_that_finished_while_orphaned_as_finished(tmp_path):
    store = Store(tmp_path / "app.sqlite")
    done = store.add_run("taxi", TREE, 512, 0, tmp_path / "runs", None)
    cut = store.add_run("taxi", TREE, 512, 0, tmp_path / "runs", None)
    for run in (done, cut):
        store.set_run_status(run["id"], "running")
    finished_dir = tmp_path / "runs" / done["id"]
    finished_dir.mkdir(parents=True)
    (finished_dir / "summary.json").write_text(json.dumps({"steps": 512, "initial_mean_return": 1.0}))
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=None, max_parallel_runs=0)
    with TestClient(app, base_url="http://127.0.0.1") as client:
        first = client.get(f"/api/runs/{done['id']}").json()
        assert first["status"] == "finished" and first["summary"]["steps"] == 512
        assert client.get(f"/api/runs/{cut['id']}").json()["status"] == "interrupted"


def test_failure_reason_is_this_attempts_own_line(tmp_path):
    from nl2policy.app.runs import failure_reason

    log = tmp_path / "log.txt"
    log.write_text("error: process 12 is still writing the run folder\n")
    start = log.stat().st_size
    with log.open("a") as fh:
        fh.write("Traceback (most recent call last):\n  File \"x.py\", line 1\nRuntimeError: out of memory\n")
    assert failure_reason(tmp_path, 1, start).startswith("RuntimeError: out of memory (full log: ")
    assert failure_reason(tmp_path, 2).startswith("process 12 is still writing")  # the whole log: its last error line
    assert failure_reason(tmp_path / "none", -9).startswith("the training process was stopped by signal 9")


def test_a_failed_run_says_why_and_does_not_resume(tmp_path):
    """A run folder holding another tree's checkpoint makes `optimize` refuse: the run fails with
    that one line as its error, not an 800-character log tail."""
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=None)
    with TestClient(app, base_url="http://127.0.0.1") as client:
        store = app.state.store
        run = store.add_run("taxi", TREE, 512, 0, tmp_path / "runs", None)
        folder = tmp_path / "runs" / run["id"]
        folder.mkdir(parents=True)
        (folder / "state.json").write_text("{}")
        (folder / "initial_tree.json").write_text(json.dumps({"do": "wait"}))
        app.state.runs.submit(run["id"])
        view = wait_until(lambda: (v := client.get(f"/api/runs/{run['id']}").json())["status"] == "failed" and v, 120,
                          "the run to fail")
        assert view["error"].startswith(f"{folder} holds a checkpoint of a run from a different tree")
        assert "Traceback" not in view["error"] and len(view["error"]) < 400
        assert client.post(f"/api/runs/{run['id']}/resume").status_code == 409
