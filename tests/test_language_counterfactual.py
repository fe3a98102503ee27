"""Counterfactual copies: actions permuted in a real description's text and tree alike."""

import random

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.augment import augment_fold
from nl2policy.language.corpus import load_corpus
from nl2policy.language.counterfactual import swap_actions
from nl2policy.language.mentions import GROUPS, find_mentions
from nl2policy.trees import Leaf, Node
from nl2policy.trees.parse import validate
from nl2policy.trees.tree import iter_leaves

TAXI_TEXT = ("If you have a passenger, drive straight to the airport. If not, check whether you are in the "
             "village: in the village, wait; anywhere else, head for the village.")
TAXI_TREE = Node("has_passenger", Leaf("go_airport"), Node("at_village", Leaf("wait"), Leaf("go_village")))


def test_taxi_destinations_are_permuted_in_text_and_tree_together():
    seen = set()
    for seed in range(20):
        text, tree = swap_actions("taxi", TAXI_TEXT, TAXI_TREE, random.Random(seed))
        validate(tree, get_domain("taxi").vocab)
        assert tree.no.yes == Leaf("wait") and tree.question == "has_passenger"  # only movement actions move
        airport, village = tree.yes.action.removeprefix("go_"), tree.no.no.action.removeprefix("go_")
        assert f"drive straight to the {airport}." in text and f"head for the {village}." in text
        assert "in the village: in the village, wait" in text  # the question's own words stay
        seen.add((airport, village))
    assert len(seen) > 2 and ("airport", "village") not in seen  # random, and never the identity


def test_highway_speed_and_lane_mentions_swap_with_their_inflection_and_case():
    text = "If a car is close ahead, move left. Otherwise Speed up; when going fast it slows down."
    tree = Node("car_ahead_close", Leaf("lane_left"), Node("going_fast", Leaf("slower"), Leaf("faster")))
    new_text, new_tree = swap_actions("highway", text, tree, random.Random(0))
    assert new_text == "If a car is close ahead, move right. Otherwise Slow down; when going fast it speeds up."
    assert new_tree == Node("car_ahead_close", Leaf("lane_right"), Node("going_fast", Leaf("faster"), Leaf("slower")))


def test_a_tree_action_the_text_is_not_seen_to_mention_leaves_the_pair_alone():
    # go_city is in the tree but the text says it only as "the town centre": a permuted copy would
    # keep a stale mention somewhere, so there is none
    tree = Node("has_passenger", Leaf("go_airport"), Leaf("go_city"))
    assert swap_actions("taxi", "Passenger: drive to the airport. Else the town centre.", tree, random.Random(0)) is None
    # a mention of an action the tree does not use: also left alone
    assert swap_actions("taxi", "Drive to the airport or drive to the city.", Node("has_passenger", Leaf("go_airport"), Leaf("wait")),
                        random.Random(0)) is None
    # an action named only by a form the patterns do not know ("keep going" for faster)
    assert swap_actions("highway", "Close ahead: slow down. Otherwise keep going.",
                        Node("car_ahead_close", Leaf("slower"), Leaf("faster")), random.Random(0)) is None


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_every_corpus_copy_is_valid_and_its_text_names_exactly_its_new_actions(domain):
    """Over the whole corpus: each copy is a valid tree, differs from the original, and what the
    patterns find in the new text is exactly the new tree's actions of each group."""
    vocab, made = get_domain(domain).vocab, 0
    for spec in load_corpus(domain):
        out = swap_actions(domain, spec.description, spec.tree, random.Random(spec.id))
        if out is None:
            continue
        made += 1
        text, tree = out
        validate(tree, vocab)
        assert tree != spec.tree
        for group in GROUPS[domain]:
            assert {a for *_, a in find_mentions(group, text)} == {l.action for l in iter_leaves(tree)} & set(group.actions), spec.id
    assert made >= len(load_corpus(domain)) // 2


def test_augment_fold_swaps_only_when_asked_and_keeps_the_pair_count():
    specs = load_corpus("taxi")
    idx = list(range(40))
    plain = augment_fold(specs, idx, 1, seed=0)
    swapped = augment_fold(specs, idx, 1, seed=0, swap=True)
    assert len(plain) == len(swapped) == 40
    assert [t for _, t in plain] == [specs[i].tree for i in idx]
    changed = sum(t != specs[i].tree for (_, t), i in zip(swapped, idx))
    assert changed >= 20
    assert swapped == augment_fold(specs, idx, 1, seed=0, swap=True)  # reproducible
