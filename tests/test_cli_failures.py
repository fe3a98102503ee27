"""Regression tests for the CLI tracebacks of issue 29: each bad input exits with code 2 and
one line ``error: ...`` before any work starts, and the CLI keeps the API's limits."""

import json
import os
import sys

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from nl2policy.app.server import create_app
from nl2policy.cli import app
from nl2policy.limits import MAX_DESCRIPTION, MAX_SEED
from test_store_faults import run_with_read_only

runner = CliRunner()
GOOD = '{"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}'


def one_error_line(result, *needles: str) -> str:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = [ln for ln in result.stderr.splitlines() if ln.strip() and not ln.startswith("note:")]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def files(tmp_path):
    binary = tmp_path / "tree.bin"
    binary.write_bytes(bytes(range(256)) * 8)
    deep = '{"do": "wait"}'
    for _ in range(3000):
        deep = f'{{"if": "at_city", "yes": {deep}, "no": {{"do": "wait"}}}}'
    (tmp_path / "deep.json").write_text(deep)
    (tmp_path / "a-file").write_text("not a folder")
    return tmp_path


def test_binary_tree_file(files):
    one_error_line(runner.invoke(app, ["evaluate", "--domain", "taxi", "--tree", str(files / "tree.bin")]), "not a UTF-8 text file")


def test_binary_jsonl_file(files):
    one_error_line(runner.invoke(app, ["translate", "--domain", "taxi", "--jsonl", str(files / "tree.bin")]),
                   "not a UTF-8 text file")


def test_3000_deep_tree(files):
    for args in (["--tree", str(files / "deep.json")], ["--tree", (files / "deep.json").read_text()]):
        one_error_line(runner.invoke(app, ["evaluate", "--domain", "taxi", *args]), "nested too deeply")


@pytest.mark.parametrize("command", [["evaluate", "--domain", "taxi", "--tree", GOOD], ["compare"],
                                     ["optimize", "--domain", "taxi", "--tree", GOOD]])
@pytest.mark.parametrize("seed", [-1, MAX_SEED + 1])
def test_out_of_range_seed(command, seed):
    one_error_line(runner.invoke(app, [*command, "--seed", str(seed)]), "--seed must be", str(seed))


@pytest.mark.parametrize("command", [["optimize", "--domain", "taxi", "--tree", GOOD, "--steps", "512"],
                                     ["run", "--steps", "512"]])
@pytest.mark.parametrize("out", ["{tmp}/a-file", "/proc", "/proc/nl2policy-out"])
def test_out_folder_that_cannot_be_written(files, command, out):
    out = out.replace("{tmp}", str(files))
    one_error_line(runner.invoke(app, [*command, "--out", out]), out)


@pytest.mark.parametrize("out,needle", [("{tmp}", "is a folder"), ("/proc", "is a folder"),
                                        ("/proc/x.jsonl", "cannot write"), ("{tmp}/no/such/x.jsonl", "does not exist")])
def test_export_out_that_cannot_be_written(files, out, needle):
    out = out.replace("{tmp}", str(files))
    one_error_line(runner.invoke(app, ["export-submissions", "--domain", "taxi", "--out", out,
                                       "--db", str(files / "app.sqlite")]), needle)


@pytest.mark.parametrize("command", [
    ["optimize", "--domain", "taxi", "--tree", GOOD, "--steps", "512", "--out", "{ro}/out"],
    ["export-submissions", "--domain", "taxi", "--db", "{tmp}/app.sqlite", "--out", "{ro}/x.jsonl"],
])
def test_out_in_a_read_only_folder(tmp_path, command):
    ro = tmp_path / "ro"
    ro.mkdir()
    args = [a.replace("{ro}", str(ro)).replace("{tmp}", str(tmp_path)) for a in command]
    proc = run_with_read_only(ro, [sys.executable, "-m", "nl2policy.cli", *args], dict(os.environ))
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: cannot write") and str(ro) in lines[0], proc.stderr


@pytest.mark.parametrize("port", ["99999", "0", "-5"])
def test_serve_on_an_impossible_port(port):
    one_error_line(runner.invoke(app, ["serve", "--port", port]), "--port must be from 1 to 65535")


def test_optimize_with_less_than_one_rollout_is_refused(tmp_path):
    one_error_line(runner.invoke(app, ["optimize", "--domain", "taxi", "--tree", GOOD, "--steps", "1",
                                       "--out", str(tmp_path / "o")]), "at least 512")
    assert not (tmp_path / "o").exists()


def test_optimize_says_when_steps_are_rounded_up(files):
    result = runner.invoke(app, ["optimize", "--domain", "taxi", "--tree", GOOD, "--steps", "600", "--out", str(files / "a-file")])
    assert "--steps 600 trains 1024 steps" in result.stderr  # said before the (bad --out) error stops it
    one_error_line(result, "a-file")


def test_cli_and_api_refuse_the_same_long_description(tmp_path):
    text = "go to the airport " * 6000  # about 100 KB
    assert len(text) > MAX_DESCRIPTION
    for command in (["translate", "--domain", "taxi", text], ["run", "--domain", "taxi", text, "--out", str(tmp_path)]):
        one_error_line(runner.invoke(app, command), f"the limit is {MAX_DESCRIPTION:,}")
    with TestClient(create_app(tmp_path / "a.sqlite", tmp_path, translator=None), base_url="http://127.0.0.1") as client:
        r = client.post("/api/translate", json={"domain": "taxi", "description": text})
        assert r.status_code == 422
    jsonl = tmp_path / "in.jsonl"
    jsonl.write_text(json.dumps({"description": text}) + "\n")
    rows = runner.invoke(app, ["translate", "--domain", "taxi", "--jsonl", str(jsonl)]).stdout.splitlines()
    assert f"the limit is {MAX_DESCRIPTION:,}" in json.loads(rows[-1])["error"]


def test_punctuation_only_description_is_one_line():
    one_error_line(runner.invoke(app, ["translate", "--domain", "taxi", "?!.,;"]), "empty")


def test_serve_on_a_port_in_use_or_a_bad_host():
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        one_error_line(runner.invoke(app, ["serve", "--port", str(port)]), f"cannot listen on 127.0.0.1:{port}")
    one_error_line(runner.invoke(app, ["serve", "--host", "no-such-host.invalid"]), "--host no-such-host.invalid")


def test_error_lines_stay_short_whatever_was_given():
    line = one_error_line(runner.invoke(app, ["evaluate", "--domain", "taxi", "--tree", json.dumps({"do": "x" * 100_000})]),
                          "unknown action")
    assert len(line) < 600 and "characters)" in line


def test_run_into_a_folder_holding_another_trees_checkpoint(tmp_path):
    (tmp_path / "taxi").mkdir()
    (tmp_path / "taxi" / "state.json").write_text("{}")
    (tmp_path / "taxi" / "initial_tree.json").write_text('{"do": "wait"}')
    result = runner.invoke(app, ["run", "--domain", "taxi", "--steps", "512", "--out", str(tmp_path)])
    one_error_line(result, "holds a checkpoint of a run from a different tree")
