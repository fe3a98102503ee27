"""The Table-2 runner on a toy budget: tree selection, finished runs skipped, table written."""

import json

import numpy as np
from typer.testing import CliRunner

from nl2policy.cli import app
from nl2policy.policy.optimize import rolling_mean

runner = CliRunner()


def test_rolling_mean_uses_the_last_window_episodes():
    assert np.allclose(rolling_mean([1, 2, 3, 4], 2), [1, 1.5, 2.5, 3.5])


def test_tiny_experiment_writes_table_and_skips_finished_runs(tmp_path):
    args = ["policy-experiment", "--domain", "taxi", "--steps", "512", "--candidates", "3", "--best", "1",
            "--select-episodes", "5", "--tree-seeds", "1", "--baseline-seeds", "1", "--out", str(tmp_path)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    table = json.loads((tmp_path / "table2_taxi.json").read_text())
    assert {r["method"] for r in table["runs"]} == {"tree_ddt", "random_ddt", "mlp"}
    assert (tmp_path / "curves_taxi.png").is_file() and "--steps 512" in (tmp_path / "table2_taxi.md").read_text()
    selected = json.loads((tmp_path / "taxi" / "selected_trees.json").read_text())
    returns = [c["mean_return"] for c in selected["candidates"]]
    assert returns == sorted(returns, reverse=True) and selected["selected"] == selected["candidates"][:1]
    run = tmp_path / "taxi" / "runs" / "mlp_s0" / "result.json"
    before = run.stat().st_mtime_ns
    assert runner.invoke(app, args).exit_code == 0  # second time: every run already finished
    assert run.stat().st_mtime_ns == before
    assert json.loads((tmp_path / "table2_taxi.json").read_text())["table"] == table["table"]
