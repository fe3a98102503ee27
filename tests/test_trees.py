"""Lexical trees: parsing, validation errors that say where, and exact round trips."""

import json
import re

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.corpus import covered_domains, load_corpus
from nl2policy.trees import (
    GRID_SLOTS, Leaf, Node, TreeError, from_grid, from_tokens, parse_tree, to_dot, to_grid, to_svg,
    to_text, to_tokens, tree_to_json,
)
from nl2policy.trees.tree import depth


@pytest.mark.parametrize("domain", sorted(covered_domains()))
def test_every_corpus_tree_round_trips(domain):
    vocab = get_domain(domain).vocab
    specs = load_corpus(domain)
    assert len(specs) == 200
    for spec in specs:
        raw = json.loads(json.dumps(tree_to_json(spec.tree)))
        assert parse_tree(raw, vocab) == spec.tree
        assert parse_tree(json.dumps(raw), vocab) == spec.tree
        tokens = to_tokens(spec.tree)
        assert from_tokens(tokens, vocab) == spec.tree
        grid = to_grid(spec.tree)
        assert len(grid) == GRID_SLOTS
        assert from_grid(grid, vocab) == spec.tree
        assert depth(spec.tree) <= 3


def test_tree_json_matches_corpus_file_exactly():
    from nl2policy.data import corpus_dir

    vocab = get_domain("taxi").vocab
    for line in (corpus_dir() / "taxi.jsonl").read_text().splitlines():
        row = json.loads(line)
        assert tree_to_json(parse_tree(row["tree"], vocab)) == row["tree"]


def test_tokens_and_grid_have_the_expected_shape(taxi):
    tree = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"},
                       "no": {"if": "heavy_traffic", "yes": {"do": "go_village"}, "no": {"do": "go_city"}}}, taxi.vocab)
    assert to_tokens(tree) == ["has_passenger", "go_airport", "heavy_traffic", "go_village", "go_city"]
    grid = to_grid(tree)
    assert grid[:7] == ["has_passenger", "go_airport", "heavy_traffic", None, None, "go_village", "go_city"]
    assert all(slot is None for slot in grid[7:])


def test_act_follows_answers(taxi):
    tree = Node("has_passenger", Leaf("go_airport"), Node("heavy_traffic", Leaf("go_village"), Leaf("go_city")))
    assert tree.act({"has_passenger": True, "heavy_traffic": True}) == "go_airport"
    assert tree.act({"has_passenger": False, "heavy_traffic": True}) == "go_village"
    assert tree.act({"has_passenger": False, "heavy_traffic": False}) == "go_city"


LEAF = {"do": "go_city"}
BAD_TREES = [
    ('{"if": "has_passenger", "yes": {"do": "go_airport"}', "malformed JSON"),
    ({"do": "fly_to_moon"}, "unknown action 'fly_to_moon'"),
    ({"if": "is_raining", "yes": LEAF, "no": {"do": "wait"}}, "unknown question 'is_raining'"),
    ({"if": "at_city", "yes": {"do": "wait"}, "no": {"if": "at_city", "yes": LEAF, "no": {"do": "wait"}}},
     "asked again on the same path"),
    ({"if": "at_city", "yes": LEAF, "no": LEAF}, "identical yes and no branches"),
    ({"if": "at_city", "yes": LEAF}, "missing ['no']"),
    ({"do": "wait", "if": "at_city"}, "not both"),
    ({"do": 3}, "must name an action id"),
    ([1, 2], "expected an object"),
    ({}, "empty object"),
    ({"if": "at_city", "yes": LEAF, "no": {"do": "wait"}, "maybe": LEAF}, "unexpected keys"),
]


@pytest.mark.parametrize("raw,message", BAD_TREES)
def test_bad_trees_raise_a_clear_error(taxi, raw, message):
    with pytest.raises(TreeError, match=re.escape(message)):
        parse_tree(raw, taxi.vocab)


def test_too_deep_tree_names_the_place(taxi):
    deep = {"if": "at_city", "yes": {"do": "wait"}, "no": {"if": "at_village", "yes": {"do": "wait"}, "no": {
        "if": "has_passenger", "yes": {"do": "go_airport"}, "no": {
            "if": "heavy_traffic", "yes": {"do": "go_village"}, "no": {"do": "go_city"}}}}}
    with pytest.raises(TreeError) as info:
        parse_tree(deep, taxi.vocab)
    assert info.value.where == "root.no.no.no"
    assert "more than 3 questions" in str(info.value)


def test_error_path_points_into_the_tree(taxi):
    with pytest.raises(TreeError) as info:
        parse_tree({"if": "at_city", "yes": {"do": "wait"}, "no": {"if": "at_airport", "yes": {"do": "nap"}, "no": LEAF}}, taxi.vocab)
    assert info.value.where == "root.no.yes"


def test_bad_token_sequences(taxi):
    with pytest.raises(TreeError, match="ends before"):
        from_tokens(["has_passenger", "go_airport"], taxi.vocab)
    with pytest.raises(TreeError, match="left after"):
        from_tokens(["go_airport", "go_city"], taxi.vocab)
    with pytest.raises(TreeError, match="unknown token"):
        from_tokens(["has_passenger", "go_airport", "teleport"], taxi.vocab)
    with pytest.raises(TreeError, match="identical"):
        from_tokens(["has_passenger", "go_city", "go_city"], taxi.vocab)


def test_bad_grids(taxi):
    with pytest.raises(TreeError, match="15 slots"):
        from_grid(["go_city"], taxi.vocab)
    grid = [None] * GRID_SLOTS
    grid[0] = "at_city"
    grid[1] = "wait"
    with pytest.raises(TreeError, match="empty slot") as info:
        from_grid(grid, taxi.vocab)
    assert info.value.where == "slot 2"
    grid[2] = "go_city"
    grid[3] = "go_airport"
    with pytest.raises(TreeError, match="hangs below") as info:
        from_grid(grid, taxi.vocab)
    assert info.value.where == "slot 3"
    bottom = [None] * GRID_SLOTS
    bottom[0], bottom[1], bottom[2], bottom[3], bottom[4] = "at_city", "at_airport", "wait", "at_village", "go_city"
    bottom[7], bottom[8] = "has_passenger", "wait"
    with pytest.raises(TreeError, match="bottom row"):
        from_grid(bottom, taxi.vocab)


def test_renderings_show_every_label(taxi):
    tree = load_corpus("taxi")[4].tree
    text = to_text(tree, taxi.vocab)
    assert text.splitlines()[0] == taxi.vocab.questions["has_passenger"]
    assert "yes: -> Drive to the airport" in text
    dot = to_dot(tree, taxi.vocab)
    assert dot.startswith("digraph") and dot.count("->") == 4
    svg = to_svg(tree, taxi.vocab, highlight={0: "#ffcdd2"})
    assert svg.startswith("<svg") and svg.count('class="question"') == 2 and svg.count('class="leaf"') == 3
    assert 'data-slot="0"' in svg and "#ffcdd2" in svg
