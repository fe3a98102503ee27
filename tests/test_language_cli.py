"""The translate/train-translator contract, and the confidence of bad input.

Uses the tiny "smoke" model (one epoch) in a temporary NL2POLICY_HOME: these tests check the
plumbing and the topic detector, not translation quality (that is the experiment's job).
"""

import json

import pytest
from typer.testing import CliRunner

from nl2policy.cli import app
from nl2policy.domains import get_domain
from nl2policy.language import translate as tr
from nl2policy.language.corpus import load_corpus
from nl2policy.trees import parse_tree, to_grid

runner = CliRunner()

pytestmark = pytest.mark.usefixtures("one_torch_thread")



@pytest.fixture(scope="module")
def home(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    path = tmp_path_factory.mktemp("nl2policy_home")
    mp.setenv("NL2POLICY_HOME", str(path))
    tr._LOADED.clear()
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    out = runner.invoke(app, ["train-translator", "--domain", "taxi", "--model", "smoke"])
    torch.set_num_threads(threads)
    assert out.exit_code == 0, out.output
    yield path
    tr._LOADED.clear()
    mp.undo()


def test_training_saves_the_model_and_no_checkpoint(home):
    assert (home / "models" / "taxi-smoke.pt").is_file()
    assert not (home / "models" / "taxi-smoke.ckpt").exists()


def test_translate_text_and_json(home):
    text = load_corpus("taxi")[0].description
    out = runner.invoke(app, ["translate", "--domain", "taxi", "--model", "smoke", text])
    assert out.exit_code == 0, out.output
    assert "confidence:" in out.stdout and "->" in out.stdout
    out = runner.invoke(app, ["translate", "--domain", "taxi", "--model", "smoke", "--json", text])
    data = json.loads(out.stdout)
    assert {"tree", "confidence", "warnings"} <= set(data)
    parse_tree(data["tree"], get_domain("taxi").vocab)
    assert 0.0 <= data["confidence"] <= 1.0


def test_jsonl_gives_one_object_per_line_in_order_with_errors(home, tmp_path):
    specs = load_corpus("taxi")
    lines = [json.dumps({"description": specs[0].description}), "{not json", json.dumps({"text": "no field"}),
             json.dumps({"description": "   "}), json.dumps({"description": specs[1].description, "id": 7})]
    path = tmp_path / "in.jsonl"
    path.write_text("\n".join(lines) + "\n")
    out = runner.invoke(app, ["translate", "--domain", "taxi", "--model", "smoke", "--jsonl", str(path)])
    assert out.exit_code == 0, out.output
    rows = [json.loads(l) for l in out.stdout.strip().splitlines()]
    assert len(rows) == 5
    assert "tree" in rows[0] and "confidence" in rows[0] and "tree" in rows[4]
    assert "not valid JSON" in rows[1]["error"]
    assert "description" in rows[2]["error"]
    assert "empty" in rows[3]["error"]


def test_bad_input_exits_non_zero(home):
    assert runner.invoke(app, ["translate", "--domain", "taxi", "--model", "smoke", "  "]).exit_code != 0
    assert runner.invoke(app, ["translate", "--domain", "boat", "--model", "smoke", "hi"]).exit_code != 0
    assert runner.invoke(app, ["translate", "--domain", "taxi", "--model", "nope", "hi"]).exit_code != 0
    assert runner.invoke(app, ["translate", "--domain", "taxi", "--model", "smoke", "--jsonl", "/no/such"]).exit_code != 0


def test_empty_description_is_an_error(home):
    with pytest.raises(tr.EmptyDescription, match="empty"):
        tr.translate("taxi", " \n ", "smoke")


def test_off_topic_and_other_domain_get_low_confidence_and_a_warning(home):
    off = tr.translate("taxi", "I really like pizza and my cat sleeps all afternoon.", "smoke")
    assert off.confidence <= 0.05 and any("off-topic" in w for w in off.warnings)
    highway_text = load_corpus("highway")[3].description
    other = tr.translate("taxi", highway_text, "smoke")
    assert other.confidence <= 0.1 and any("highway" in w for w in other.warnings)
    for spec in load_corpus("taxi")[:40]:
        own = tr.translate("taxi", spec.description, "smoke")
        assert not any("off-topic" in w or "reads like" in w for w in own.warnings), spec.id
        grid = to_grid(own.tree)
        assert set(own.node_confidence) == {i for i, x in enumerate(grid) if x is not None}
        assert all(0.0 <= p <= 1.0 for p in own.node_confidence.values())


def test_a_tree_that_never_takes_a_named_action_is_flagged(home, monkeypatch):
    """The warning names each action the text names and the tree never takes (mentions.py)."""
    vocab = get_domain("taxi").vocab
    habit = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_village"}}, vocab)
    loaded = tr.get_model("taxi", "smoke")
    monkeypatch.setattr(loaded.translator, "predict", lambda texts: [(habit, {0: 0.9, 1: 0.9, 2: 0.9})])
    said = tr.translate("taxi", "With a passenger drive to the airport, otherwise drive to the city.", "smoke")
    assert said.tree == habit and [w for w in said.warnings if "never does" in w] == [
        "the description says to drive to the city (go_city), but the tree never does: check where it should"]
    plain = tr.translate("taxi", "With a passenger drive to the airport, otherwise drive to the village.", "smoke")
    assert plain.warnings == []


def test_a_tree_that_never_asks_a_question_the_text_asks_is_flagged(home, monkeypatch):
    """The warning names each question the text asks and the tree never does (mentions.py)."""
    vocab = get_domain("taxi").vocab
    habit = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}, vocab)
    loaded = tr.get_model("taxi", "smoke")
    monkeypatch.setattr(loaded.translator, "predict", lambda texts: [(habit, {0: 0.9, 1: 0.9, 2: 0.9})])
    warning = 'the description asks "is the taxi in the city?" (at_city), but the tree never does: check where it should'
    said = tr.translate("taxi", "With a passenger drive to the airport. If you are in the city, wait; "
                                "otherwise drive to the city.", "smoke")
    assert [w for w in said.warnings if "check where it should" in w] == [warning]
    # the extended forms too (a list header), whatever forms the model's own check uses
    listed = tr.translate("taxi", "- passenger: drive to the airport\n- in the city: wait\n- elsewhere: drive to the city",
                          "smoke")
    assert [w for w in listed.warnings if "check where it should" in w] == [warning]


def _rule_warnings(monkeypatch, tree: dict, text: str) -> list[str]:
    """The rule warnings `translate` gives `text` when the smoke model's decoding returns `tree`."""
    tree = parse_tree(tree, get_domain("taxi").vocab)
    loaded = tr.get_model("taxi", "smoke")
    monkeypatch.setattr(loaded.translator, "predict", lambda texts: [(tree, {0: 0.9, 1: 0.9, 2: 0.9, 4: 0.9, 5: 0.9})])
    return [w for w in tr.translate("taxi", text, "smoke").warnings if "that there" in w]


_HABIT = {"if": "has_passenger", "yes": {"do": "go_airport"},
          "no": {"if": "at_village", "yes": {"do": "wait"}, "no": {"do": "go_village"}}}
_ASKS = {"if": "heavy_traffic", "yes": {"do": "go_village"},
         "no": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}}


@pytest.mark.parametrize("tree, text, warning", [
    # a plain rule that no branch of the tree follows
    (_HABIT, "With a passenger, drive to the airport. In the village, wait. No passenger and not in the village: go "
             "to the city.",
     'the description says "No passenger and not in the village: go to the city", but the tree never does that there: '
     'check that branch'),
    # "..., no matter what": some branch under its condition does something else (extended forms,
    # whatever forms the model's own check reads)
    (_ASKS, "When the road is jammed, go to the village. When it's clear, drive to the city, no matter what.",
     'the description says "When it\'s clear, drive to the city, no matter what", but the tree does not always do that '
     'there: check that branch'),
])
def test_a_tree_that_breaks_a_rule_the_text_states_is_flagged(home, monkeypatch, tree, text, warning):
    """The warning quotes each rule the text states that the tree breaks (stated_rules.py)."""
    assert _rule_warnings(monkeypatch, tree, text) == [warning]


def test_a_tree_that_asks_another_question_first_than_the_text_says_is_flagged(home, monkeypatch):
    vocab = get_domain("taxi").vocab
    tree = parse_tree({"if": "at_city", "yes": {"do": "wait"}, "no": {"do": "go_city"}}, vocab)
    loaded = tr.get_model("taxi", "smoke")
    monkeypatch.setattr(loaded.translator, "predict", lambda texts: [(tree, {0: 0.9, 1: 0.9, 2: 0.9})])
    top = lambda text: [w for w in tr.translate("taxi", text, "smoke").warnings if "check its top" in w]
    assert top("First check whether there is a passenger. In the city, wait; elsewhere drive to the city.") == [
        'the description says to ask first "does the taxi have a passenger?" (has_passenger), but the tree asks '
        'something else first: check its top']
    assert top("First check whether you are in the city: if so wait, if not drive to the city.") == []


def test_highway_warnings_name_the_question_without_its_note(home, monkeypatch):
    """Highway's questions are read too (mentions.py, stated_rules.first_question); a warning quotes
    the dictionary's question without the note after it."""
    tree = parse_tree({"if": "car_ahead_close", "yes": {"do": "slower"}, "no": {"do": "faster"}}, get_domain("highway").vocab)
    loaded = tr.get_model("highway", "smoke")
    monkeypatch.setattr(loaded.translator, "predict", lambda texts: [(tree, {0: 0.9, 1: 0.9, 2: 0.9})])
    said = tr.translate("highway", "First check whether the lane to the right is free: if it is, move right. "
                                   "If not, slow down when a car is close in front, else speed up.", "smoke")
    assert [w for w in said.warnings if "(right_lane_free)" in w] == [
        'the description asks "is the lane to my right free?" (right_lane_free), but the tree never does: check where it '
        'should',
        'the description says to ask first "is the lane to my right free?" (right_lane_free), but the tree asks '
        'something else first: check its top']
