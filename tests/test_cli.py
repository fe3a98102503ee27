"""The command line: JSON out, reproducible, and bad input exits non-zero with a reason."""

import json
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from nl2policy.cli import app

runner = CliRunner()
GOOD = '{"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}'


def test_evaluate_prints_json_and_is_reproducible():
    args = ["evaluate", "--domain", "taxi", "--tree", GOOD, "--episodes", "30", "--seed", "7"]
    first = runner.invoke(app, args)
    assert first.exit_code == 0, first.output
    result = json.loads(first.stdout.strip().splitlines()[-1])
    assert set(result) == {"mean_return", "stderr", "episodes"} and result["episodes"] == 30
    assert result["mean_return"] > 3
    second = runner.invoke(app, args)
    assert json.loads(second.stdout.strip().splitlines()[-1]) == result


def test_evaluate_reads_a_tree_file(tmp_path):
    path = tmp_path / "tree.json"
    path.write_text(GOOD)
    out = runner.invoke(app, ["evaluate", "--domain", "taxi", "--tree", str(path), "--episodes", "2"])
    assert out.exit_code == 0, out.output


@pytest.mark.parametrize("tree,message", [
    ('{"if": "has_passenger", "yes": {"do": "go_airport"}', "malformed JSON"),
    ('{"do": "teleport"}', "unknown action 'teleport'"),
    ('{"if": "raining", "yes": {"do": "wait"}, "no": {"do": "go_city"}}', "unknown question 'raining'"),
    ('{"if": "at_city", "yes": {"do": "wait"}, "no": {"do": "wait"}}', "identical yes and no branches"),
    ('{"if": "at_city", "yes": {"do": "wait"}, "no": {"if": "at_city", "yes": {"do": "wait"}, "no": {"do": "go_city"}}}',
     "asked again"),
    ("no/such/file.json", "no such file"),
])
def test_bad_tree_exits_nonzero_with_the_problem(tree, message):
    out = runner.invoke(app, ["evaluate", "--domain", "taxi", "--tree", tree])
    assert out.exit_code == 2
    assert message in out.output


def test_unknown_domain_exits_nonzero():
    out = runner.invoke(app, ["evaluate", "--domain", "boat", "--tree", GOOD])
    assert out.exit_code == 2 and "unknown domain 'boat'" in out.output


def test_installed_entry_point_runs():
    proc = subprocess.run([sys.executable, "-m", "nl2policy.cli", "evaluate", "--domain", "taxi", "--tree", GOOD,
                           "--episodes", "3"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["episodes"] == 3
    bad = subprocess.run([sys.executable, "-m", "nl2policy.cli", "evaluate", "--domain", "taxi", "--tree", "{"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "malformed JSON" in bad.stderr


def test_run_says_what_an_unsure_translator_asks_and_where_to_answer(tmp_path, monkeypatch):
    """The main job optimizes the tree it was given; when the translator is unsure it shows the
    question it would ask and the two places to answer it, before PPO starts."""
    import nl2policy.language.translate as translate_module
    import nl2policy.policy.optimize as optimize_module
    from nl2policy.domains import get_domain
    from nl2policy.language.clarify import question_for, situations
    from nl2policy.trees import parse_tree

    vocab = get_domain("taxi").vocab
    question = question_for("taxi", situations("taxi")[0])
    unsure = translate_module.Translation(parse_tree({"do": "wait"}, vocab), 0.2, [], {}, [question])
    monkeypatch.setattr(translate_module, "translate", lambda domain, text: unsure)

    def refuse(*args, **kwargs):
        raise optimize_module.OptimizeRefused("stopped here by the test")
    monkeypatch.setattr(optimize_module, "optimize_tree", refuse)
    result = runner.invoke(app, ["run", "--domain", "taxi", "wait at the rank", "--out", str(tmp_path)])
    assert result.exit_code == 2
    said = " ".join(result.output.split())
    assert f"the translator asks: {' '.join(question.text.split())}" in said
    assert "--interactive" in said and "Specify page" in said
