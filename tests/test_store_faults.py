"""Regression tests for database faults (issue 29): an empty, garbage, truncated or damaged
database file, or a read-only data folder, gives one clear line naming the file and what to do,
and the file is left exactly as it was (never silently replaced by a new, empty database)."""

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from nl2policy.app.store import Store, StoreError
from nl2policy.cli import app

runner = CliRunner()


def real_database(path: Path) -> Path:
    """A valid app database with enough rows to span many pages."""
    Store(path)
    with sqlite3.connect(path) as db:  # one transaction: 300 separate ones cost seconds of fsync
        db.executemany("INSERT INTO submissions VALUES (?,?,?,?,?,?)",
                       [(f"s{i}", "taxi", f"w{i}", '{"do": "wait"}', "x" * 400, 0.0) for i in range(300)])
    with sqlite3.connect(path) as db:
        db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    assert path.stat().st_size > 4096 * 8
    return path


def make_zero(path):
    path.write_bytes(b"")


def make_garbage(path):
    path.write_bytes(os.urandom(5000))


def make_truncated(path):
    data = real_database(path).read_bytes()
    path.write_bytes(data[: len(data) // 3])


def make_damaged(path):
    data = bytearray(real_database(path).read_bytes())
    data[4096 * 3: 4096 * 5] = os.urandom(8192)  # pages in the middle overwritten
    path.write_bytes(bytes(data))


FAULTS = {"empty": make_zero, "garbage": make_garbage, "truncated": make_truncated, "damaged": make_damaged}


@pytest.mark.parametrize("fault", FAULTS)
def test_a_bad_database_is_refused_and_left_alone(tmp_path, fault):
    path = tmp_path / "nl2policy.sqlite"
    FAULTS[fault](path)
    before = path.read_bytes()
    with pytest.raises(StoreError) as exc:
        Store(path)
    assert str(path) in str(exc.value) and "Move it aside" in str(exc.value)
    assert path.read_bytes() == before


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("command", [["serve", "--port", "1"], ["export-submissions", "--domain", "taxi", "--out", "{out}"]])
def test_cli_names_the_bad_database_in_one_line(tmp_path, fault, command):
    path = tmp_path / "nl2policy.sqlite"
    FAULTS[fault](path)
    before = path.read_bytes()
    args = [a.replace("{out}", str(tmp_path / "out.jsonl")) for a in command] + ["--db", str(path)]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: the database") and str(path) in lines[0]
    assert "Traceback" not in result.output
    assert path.read_bytes() == before


READ_ONLY = 'mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" "$0" && exec "$@"'


def run_with_read_only(folder: Path, args: list[str], env: dict) -> subprocess.CompletedProcess:
    """Run a command with `folder` read-only. Root ignores file modes, so as root the folder is
    bind-mounted read-only in a private mount namespace (nothing outside the command sees it)."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        return subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    return subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", READ_ONLY, str(folder), *args],
                          env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("home_inside", [False, True])
def test_read_only_home_names_the_path(tmp_path, home_inside):
    folder = tmp_path / "ro"
    folder.mkdir()
    home = folder / "sub" if home_inside else folder  # a home to create, or a home to write the database in
    env = {**os.environ, "NL2POLICY_HOME": str(home)}
    for args in (["export-submissions", "--domain", "taxi", "--out", str(tmp_path / "o.jsonl")], ["serve", "--port", "1"]):
        proc = run_with_read_only(folder, [sys.executable, "-m", "nl2policy.cli", *args], env)
        assert proc.returncode == 2, proc.stderr
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: cannot") and str(home) in lines[0], proc.stderr


def test_translate_works_when_the_data_folder_cannot_be_made(tmp_path):
    """The shipped translator needs no data folder; an unwritable one only means nothing is cached."""
    folder = tmp_path / "ro"
    folder.mkdir()
    env = {**os.environ, "NL2POLICY_HOME": str(folder / "sub")}
    proc = run_with_read_only(folder, [sys.executable, "-m", "nl2policy.cli", "translate", "--domain", "taxi", "--json",
                                       "If I have a passenger go to the airport, else go to the city"], env)
    assert proc.returncode == 0, proc.stderr[-1000:]
    assert "Traceback" not in proc.stderr and json.loads(proc.stdout)["tree"]["if"] == "has_passenger"


def test_a_run_submitted_before_the_reconcile_is_not_marked_left_over(tmp_path):
    """On a busy machine the run manager's thread may reconcile after the first request has
    queued a run: that run stays queued; a run left by an earlier server is interrupted."""
    from nl2policy.app.runs import RunManager

    store = Store(tmp_path / "app.sqlite")
    tree = {"do": "wait"}
    left = store.add_run("taxi", tree, 512, 0, tmp_path / "runs", None)
    fresh = store.add_run("taxi", tree, 512, 0, tmp_path / "runs", None)
    manager = RunManager(store)  # not started: no trainer is launched
    manager.submit(fresh["id"])
    manager.reconcile()
    assert store.get_run(fresh["id"])["status"] == "queued"
    assert store.get_run(left["id"])["status"] == "interrupted"
