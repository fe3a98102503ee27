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


def _findings(domain, asks=(), takes=(), root=None, p=0.9):
    """Findings that say the text asks `asks`, takes `takes` and puts `root` first (probability p)."""
    from nl2policy.language.findings import Findings

    vocab = get_domain(domain).vocab
    labels = list(vocab.question_ids) + list(vocab.action_ids)
    rest = (1 - p) / (len(labels) - 1)
    return Findings({q: p if q in asks else 1 - p for q in vocab.question_ids},
                    {a: p if a in takes else 1 - p for a in vocab.action_ids},
                    {l: p if l == root else rest for l in labels})


def _warnings(monkeypatch, domain, tree, found, text="Some words about the taxi and the city."):
    """The warnings `translate` gives when the smoke model decodes `tree` and reads `found`."""
    tree = parse_tree(tree, get_domain(domain).vocab)
    loaded = tr.get_model(domain, "smoke")
    seen = []

    def predict(texts, found=None):
        seen.append(found)
        return [(tree, {i: 0.9 for i, x in enumerate(to_grid(tree)) if x is not None})]

    monkeypatch.setattr(loaded.translator, "predict", predict)
    monkeypatch.setattr(loaded.translator, "read_findings", lambda texts: [found])
    said = tr.translate(domain, text, "smoke")
    assert said.tree == tree and seen == [[found]]  # decoding got the very findings the warnings read
    return said.warnings


_HABIT = {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_village"}}


def test_a_tree_that_agrees_with_the_findings_gets_no_warning(home, monkeypatch):
    found = _findings("taxi", asks={"has_passenger"}, takes={"go_airport", "go_village"}, root="has_passenger")
    assert _warnings(monkeypatch, "taxi", _HABIT, found) == []


def test_an_action_or_question_the_text_seems_to_use_and_the_tree_never_does_is_flagged(home, monkeypatch):
    found = _findings("taxi", asks={"has_passenger", "at_city"}, takes={"go_airport", "go_village", "go_city"},
                      root="has_passenger")
    assert _warnings(monkeypatch, "taxi", _HABIT, found) == [
        "the description seems (90%) to say to drive to the city (go_city), but the tree never does: check where it should",
        'the description seems (90%) to ask "is the taxi in the city?" (at_city), but the tree never does: check where '
        "it should"]


def test_a_question_the_tree_asks_and_the_text_does_not_seem_to_is_flagged(home, monkeypatch):
    found = _findings("taxi", takes={"go_airport", "go_village"}, root="go_airport")
    warnings = _warnings(monkeypatch, "taxi", _HABIT, found)
    assert warnings == ['the tree asks "does the taxi have a passenger?" (has_passenger), which the description does '
                        "not seem (10%) to ask: check that branch"]  # a root that is an action is no question to ask first


def test_another_first_question_than_the_text_seems_to_ask_first_is_flagged(home, monkeypatch):
    found = _findings("taxi", asks={"has_passenger", "at_city"}, takes={"go_airport", "go_village"}, root="at_city")
    tree = {"if": "has_passenger", "yes": {"do": "go_airport"},
            "no": {"if": "at_city", "yes": {"do": "go_village"}, "no": {"do": "go_airport"}}}
    assert _warnings(monkeypatch, "taxi", tree, found) == [
        'the description seems (90%) to ask first "is the taxi in the city?" (at_city), but the tree asks something else '
        "first: check its top"]


def test_an_off_topic_text_gets_no_findings_warnings(home, monkeypatch):
    found = _findings("taxi", asks={"at_city"}, takes={"go_city"}, root="at_city")
    warnings = _warnings(monkeypatch, "taxi", _HABIT, found, text="Bake the bread at two hundred degrees for an hour.")
    assert warnings and not any("seems" in w or "seem " in w for w in warnings)


def test_highway_warnings_name_the_question_without_its_note(home, monkeypatch):
    """A warning quotes the dictionary's question without the note after it."""
    found = _findings("highway", asks={"car_ahead_close", "right_lane_free"}, takes={"slower", "faster"},
                      root="right_lane_free")
    tree = {"if": "car_ahead_close", "yes": {"do": "slower"}, "no": {"do": "faster"}}
    warnings = _warnings(monkeypatch, "highway", tree, found, text="If the lane to the right is free, move right. "
                                                                    "Slow down when a car is close in front.")
    assert [w for w in warnings if "(right_lane_free)" in w] == [
        'the description seems (90%) to ask "is the lane to my right free?" (right_lane_free), but the tree never does: '
        "check where it should",
        'the description seems (90%) to ask first "is the lane to my right free?" (right_lane_free), but the tree asks '
        "something else first: check its top"]
