"""Experiment grids on Ray (issue 30): the same result files as the local runner, and a grid
that survives a killed worker. Each Ray test starts an embedded Ray of 2 CPUs (a few seconds)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from experiments.grid import LOCAL, Job, normalize_ray_flag, ray_failure, run_jobs

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("ray")]  # one Ray at a time: the kill test finds its workers by name

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def _square(x: int) -> int:
    return x * x


def test_ray_flag_without_a_value_means_a_local_ray_and_jobs_run_the_same_everywhere():
    assert normalize_ray_flag(["table2", "--ray"]) == ["table2", "--ray", LOCAL]
    assert normalize_ray_flag(["--ray", "--steps", "5"]) == ["--ray", LOCAL, "--steps", "5"]
    assert normalize_ray_flag(["--ray", "10.0.0.5:6379"]) == ["--ray", "10.0.0.5:6379"]
    assert normalize_ray_flag(["--steps", "5"]) == ["--steps", "5"]
    jobs = [Job(str(i), _square, {"x": i}) for i in range(5)]
    here, forked = {}, {}
    run_jobs(jobs, lambda job, r: here.__setitem__(job.name, r))
    run_jobs(jobs, lambda job, r: forked.__setitem__(job.name, r), processes=2)
    assert here == forked == {str(i): i * i for i in range(5)}
    assert ray_failure(ValueError("mine")) is None  # a bug of ours is not dressed up as Ray's


def test_an_unreachable_cluster_address_is_one_clear_line_at_once(tmp_path):
    from experiments.policy.__main__ import app

    started = time.time()
    result = runner.invoke(app, ["table2", "--domain", "taxi", "--steps", "512", "--candidates", "2",
                                 "--best", "1", "--select-episodes", "1", "--tree-seeds", "1", "--baseline-seeds", "1",
                                 "--out", str(tmp_path), "--ray", "127.0.0.1:1"])
    assert result.exit_code == 2 and time.time() - started < 60
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("error: the Ray grid stopped: ConnectionError: cannot reach a Ray cluster at 127.0.0.1:1")


def _without_timing(result: dict) -> dict:
    return {k: v for k, v in result.items() if k not in ("seconds", "workers", "polish_seconds")}


def test_policy_experiment_on_ray_writes_what_the_local_runner_writes(tmp_path):
    from experiments.policy.__main__ import app

    args = ["table2", "--domain", "taxi", "--steps", "1024", "--candidates", "2", "--best", "1",
            "--select-episodes", "1", "--tree-seeds", "1", "--baseline-seeds", "1"]
    local = runner.invoke(app, args + ["--out", str(tmp_path / "local")])
    assert local.exit_code == 0, local.output
    on_ray = runner.invoke(app, args + ["--out", str(tmp_path / "ray"), "--ray", LOCAL])
    assert on_ray.exit_code == 0, on_ray.output
    names = sorted(p.name for p in (tmp_path / "local" / "taxi" / "runs").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "ray" / "taxi" / "runs").iterdir()) and len(names) == 3
    for name in names:
        a, b = (json.loads((tmp_path / side / "taxi" / "runs" / name / "result.json").read_text()) for side in ("local", "ray"))
        assert _without_timing(a) == _without_timing(b), name
    tables = [json.loads((tmp_path / side / "table2_taxi.json").read_text()) for side in ("local", "ray")]
    assert tables[0]["table"] == tables[1]["table"]


def test_translation_experiment_on_ray_writes_the_folds_the_local_runner_writes(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]))
    base = [sys.executable, "-m", "experiments.translation", "--domain", "taxi", "--plan", "smoke:cv1"]
    for side, extra in (("local", []), ("ray", ["--ray"])):
        done = subprocess.run(base + ["--out", str(tmp_path / side)] + extra, cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
    folds = {}
    for side in ("local", "ray"):
        lines = [json.loads(l) for l in (tmp_path / side / "runs.jsonl").read_text().splitlines()]
        folds[side] = {r["fold"]: _without_timing(r) for r in lines}
    assert len(folds["local"]) == 5 and folds["local"] == folds["ray"]


def test_a_killed_ray_worker_restarts_its_run_from_the_checkpoint_and_the_grid_completes(tmp_path):
    """kill -9 the worker running a PPO run after its first checkpoint: Ray starts the task again,
    it resumes from checkpoint.zip, and the grid finishes; the same grid again skips it all."""
    out = tmp_path / "grid"
    STEPS = 5120  # 5 checkpoints of 1,024 steps: a run lasts long enough to be killed mid-way
    cmd = [sys.executable, "-m", "experiments.policy", "table2", "--domain", "taxi", "--steps", str(STEPS),
           "--candidates", "2", "--best", "1", "--select-episodes", "1", "--tree-seeds", "1", "--baseline-seeds", "1",
           "--out", str(out), "--ray"]
    driver = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline, killed = time.time() + 300, None
        while killed is None and time.time() < deadline and driver.poll() is None:
            states = list((out / "taxi" / "runs").glob("*/state.json")) if (out / "taxi" / "runs").is_dir() else []
            started = [s for s in states if json.loads(s.read_text())["steps"] < STEPS]
            if started:
                pids = subprocess.run(["pgrep", "-f", "ray::run_one"], capture_output=True, text=True).stdout.split()
                if pids:
                    os.kill(int(pids[0]), signal.SIGKILL)
                    killed = int(pids[0])
            time.sleep(0.5)
        assert killed is not None, "no run reached a checkpoint to kill"
        stdout, stderr = driver.communicate(timeout=600)
    finally:
        if driver.poll() is None:
            driver.kill()
    assert driver.returncode == 0, stderr[-2000:]
    results = [json.loads(p.read_text()) for p in (out / "taxi" / "runs").glob("*/result.json")]
    assert len(results) == 3 and all(r["steps"] >= STEPS for r in results)
    # the same grid again skips every finished run (on the local runner: no second Ray start)
    again = subprocess.run(cmd[:-1], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "3 of 3" in (out / "table2_taxi.md").read_text()
