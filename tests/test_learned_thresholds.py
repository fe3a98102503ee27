"""A learned threshold test (``raw:<feature><op><value>``) is a question a person can read, in the
domain's units, and every command and page that takes a tree takes it back."""

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from nl2policy.domains import get_domain
from nl2policy.policy.convert import ddt_to_tree, tree_act_fn, tree_to_ddt
from nl2policy.trees import TreeError, from_grid, parse_raw, parse_tree, to_grid, to_text, tree_to_json

LEARNED = {"if": "raw:gap_behind<0.2281",
           "yes": {"if": "raw:right_clearance>0.2136", "yes": {"do": "lane_right"}, "no": {"do": "faster"}},
           "no": {"if": "car_ahead_close", "yes": {"do": "slower"}, "no": {"do": "idle"}}}


@pytest.fixture(scope="module")
def highway():
    return get_domain("highway")


def test_a_learned_test_reads_in_the_domains_units(highway):
    vocab = highway.vocab
    assert vocab.wording("raw:gap_behind<0.2281") == "Is the gap to the car behind in my lane less than 22.8 m?"
    assert vocab.wording("raw:speed>0.6") == "Is my speed more than 24 m/s?"
    text = to_text(parse_tree(LEARNED, vocab), vocab)
    assert "Is the room in the lane to my right more than 21.4 m?" in text and "raw:" not in text
    # a domain without a [units] table reads the feature's id in its own units
    assert get_domain("taxi").vocab.wording("raw:heavy_traffic>0.3") == "Is heavy_traffic more than 0.3?"


def test_a_learned_test_goes_through_json_and_the_grid_and_acts_on_its_feature(highway):
    tree = parse_tree(json.dumps(LEARNED), highway.vocab)
    assert tree_to_json(tree) == LEARNED
    assert from_grid(to_grid(tree), highway.vocab) == tree
    x = np.zeros(len(highway.features))
    x[highway.features.index("gap_behind")] = 0.1  # a car close behind
    x[highway.features.index("right_clearance")] = 0.5  # room on the right
    assert highway.actions[highway.tree_action(tree, x)] == "lane_right"
    x[highway.features.index("right_clearance")] = 0.2
    assert highway.actions[tree_act_fn("highway", tree)(x)] == "faster"
    batch = np.random.default_rng(0).uniform(size=(200, len(highway.features)))
    assert list(highway.tree_actions(tree, batch)) == [highway.tree_action(tree, row) for row in batch]


def test_a_tree_with_learned_tests_becomes_a_ddt_that_reads_back_the_same(highway):
    tree = parse_tree(LEARNED, highway.vocab)
    assert ddt_to_tree("highway", tree_to_ddt("highway", tree)) == tree


@pytest.mark.parametrize("question", ["raw:wheels<0.2", "raw:gap_behind<abc", "raw:gap_behind<nan",
                                      "raw:gap_behind=0.2", "raw:gap_behind<0.2<0.3", "raw:"])
def test_a_malformed_learned_test_is_refused_and_says_how_one_reads(highway, question):
    assert parse_raw(question) is None or parse_raw(question).feature not in highway.features
    with pytest.raises(TreeError, match="raw:<feature>"):
        parse_tree({"if": question, "yes": {"do": "faster"}, "no": {"do": "idle"}}, highway.vocab)


def test_the_cli_evaluates_a_tree_with_learned_tests(tmp_path):
    from nl2policy.cli import app

    path = tmp_path / "learned.json"
    path.write_text(json.dumps(LEARNED))
    result = CliRunner().invoke(app, ["evaluate", "--domain", "highway", "--tree", str(path), "--episodes", "1"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output.strip().splitlines()[-1])["episodes"] == 1


def test_the_app_lists_units_shows_and_edits_a_tree_with_learned_tests(tmp_path):
    from dataclasses import dataclass, field

    from nl2policy.app.server import create_app

    @dataclass
    class Translation:
        tree: object
        confidence: float = 0.9
        warnings: list = field(default_factory=list)
        node_confidence: dict = field(default_factory=dict)

    vocab = get_domain("highway").vocab
    app = create_app(tmp_path / "app.sqlite", tmp_path, translator=lambda d, t: Translation(parse_tree(LEARNED, vocab)),
                     results_dir=tmp_path / "results")
    with TestClient(app, base_url="http://127.0.0.1") as client:
        units = client.get("/api/domains").json()["highway"]["units"]
        assert units["gap_ahead"] == {"name": "the gap to the car ahead in my lane", "scale": 100.0, "unit": "m"}
        spec = client.post("/api/translate", json={"domain": "highway", "description": "anything"}).json()
        assert spec["grid"][0] == "raw:gap_behind<0.2281" and "less than 22.8 m" in spec["svg"]
        grid = list(spec["grid"])
        grid[4] = "slower"  # an edit elsewhere keeps the learned tests
        edited = client.put(f"/api/specs/{spec['spec_id']}", json={"domain": "highway", "grid": grid})
        assert edited.status_code == 200, edited.text
        assert edited.json()["grid"] == grid
        bad = client.put(f"/api/specs/{spec['spec_id']}", json={"domain": "highway", "grid": ["raw:wheels<0.2"] + grid[1:]})
        assert bad.status_code == 422 and "raw:<feature>" in bad.text
        assert client.get(f"/api/specs/{spec['spec_id']}").json()["grid"] == grid  # the bad edit changed nothing


@pytest.mark.parametrize("value,text", [(22.81, "22.8"), (1.125, "1.13"), (2.675, "2.67"), (-0.0, "0"), (0.0, "0"),
                                        (24.000000000000004, "24"), (2e6, "2000000"), (100.0, "100"), (0.5, "0.5"),
                                        (-3.14159, "-3.14")])
def test_amounts_are_written_as_the_pages_javascript_writes_them(value, text):
    """Number(v.toPrecision(3)) in the pages: 3 significant digits of the exact value, halves up,
    no exponent at these sizes (the values are checked against what node printed for them)."""
    from nl2policy.trees.raw import three_digits

    assert three_digits(value) == text


def test_an_id_is_stored_one_way_and_the_corpus_and_submissions_refuse_learned_tests(highway, tmp_path):
    tree = parse_tree({"if": "raw:speed>0.6", "yes": {"do": "faster"}, "no": {"do": "idle"}}, highway.vocab)
    assert tree.question == "raw:speed>0.6000"
    with pytest.raises(TreeError, match="unknown question"):
        parse_tree(LEARNED, highway.vocab.dictionary_only())
