"""The rules a description states outright, and the trees that break them (stated_rules.py)."""

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.stated_rules import broken_rules, first_question, stated_rules
from nl2policy.trees import parse_tree


def _rules(text: str) -> list[tuple[dict, str]]:
    return [(dict(r.condition), r.action) for r in stated_rules("taxi", text)]


@pytest.mark.parametrize("text, rules", [
    ("3. No passenger and not in the village: go to the city.",
     [({"has_passenger": False, "at_village": False}, "go_city")]),
    ("If the traffic is heavy, it drives to the village; when it is light, it drives to the city.",
     [({"heavy_traffic": True}, "go_village"), ({"heavy_traffic": False}, "go_city")]),
    ("a) in the village \u2192 leave for the city", [({"at_village": True}, "go_city")]),
    ("If it does not have a passenger, it drives to the city.", [({"has_passenger": False}, "go_city")]),
    ("Passengers always go to the airport.", [({"has_passenger": True}, "go_airport")]),
    # not plain statements: asked, conditional after the action, answered both ways, no answer
    ("It checks whether it is in the city and then drives to the airport.", []),
    ("In the village, wait for a passenger unless the wait is long.", []),
    ("A taxi with a passenger and a taxi without one both drive to the city.", []),
    ("If not, it drives to the city.", []),
    ("It waits in the city for a passenger.", []),
])
def test_rules_a_text_states(text, rules):
    assert _rules(text) == rules


def _read(text: str) -> list[tuple[dict, str, bool]]:
    return [(dict(r.condition), r.action, r.every) for r in stated_rules("taxi", text, "extended")]


@pytest.mark.parametrize("text, rules", [
    ("When it's clear, I drive to the city, no matter what.", [({"heavy_traffic": False}, "go_city", True)]),
    ("Not in the city? Drive to the city, always.", [({"at_city": False}, "go_city", True)]),
    ("Sitting at the airport? Drive to the city.", [({"at_airport": True}, "go_city", False)]),
    ("When taxi is not in city, anywhere else, with passenger or without, it drive to the city.",
     [({"at_city": False}, "go_city", True)]),
    # a quantifier in the reason quantifies the reason, not the rule
    ("If the traffic is light, it drives to the city, since the city always has people.",
     [({"heavy_traffic": False}, "go_city", False)]),
    # an answered question whose answer opens the next clause is not read as a rule
    ("Is the road jammed? If not, go to the city.", []),
])
def test_the_extended_forms_also_read_quantified_rules_and_answered_questions(text, rules):
    assert _read(text) == rules
    assert all(r.text in text for r in stated_rules("taxi", text, "extended"))  # quoted as written, for the warning
    assert all(not r.every for r in stated_rules("taxi", text))  # the plain forms never read a quantifier
    with pytest.raises(ValueError, match="rule forms"):
        stated_rules("taxi", text, "all")


def test_a_quantified_rule_is_broken_by_any_state_under_it_that_gets_another_action():
    vocab = get_domain("taxi").vocab
    asks = parse_tree({"if": "heavy_traffic", "yes": {"do": "go_village"},
                       "no": {"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}}, vocab)
    said = parse_tree({"if": "heavy_traffic", "yes": {"do": "go_village"}, "no": {"do": "go_city"}}, vocab)
    text = "When it's clear, I drive to the city, no matter what."
    assert [r.action for r in broken_rules("taxi", text, asks, forms="extended")] == ["go_city"]
    assert broken_rules("taxi", text, asks) == []  # the plain reading: some clear state goes to the city
    assert broken_rules("taxi", text, said, forms="extended") == []
    # waiting where the rule sends you is going there: "short wait means the village, always"
    stays = parse_tree({"if": "at_village", "yes": {"do": "wait"}, "no": {"do": "go_village"}}, vocab)
    assert broken_rules("taxi", "If the wait is short, drive to the village, always.", stays, forms="extended") == []


def test_a_tree_breaks_a_rule_when_no_state_meeting_its_condition_gets_its_action():
    vocab = get_domain("taxi").vocab
    habit = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"},
                        "no": {"if": "at_village", "yes": {"do": "wait"}, "no": {"do": "go_village"}}}, vocab)
    said = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"},
                       "no": {"if": "at_village", "yes": {"do": "wait"}, "no": {"do": "go_city"}}}, vocab)
    text = "With a passenger, drive to the airport. No passenger and not in the village: go to the city."
    assert [r.action for r in broken_rules("taxi", text, habit)] == ["go_city"]
    assert broken_rules("taxi", text, said) == []
    # context the clause leaves out only narrows the states: "in the village, wait" holds for
    # the empty taxi alone, and the tree that drives a passenger to the airport does not break it
    assert broken_rules("taxi", "In the village, wait.", said) == []
    assert stated_rules("highway", "If the left lane is free, move left.") == ()  # no answer patterns in highway


def test_no_writers_tree_breaks_a_rule_its_description_states():
    """The precision the check and the warning rest on (stated_rules.py's docstring), while rules
    are found in most descriptions."""
    specs = load_corpus("taxi")
    assert sum(bool(stated_rules("taxi", s.description)) for s in specs) >= 120
    for forms in ("plain", "extended"):
        assert [s.id for s in specs if broken_rules("taxi", s.description, s.tree, forms=forms)] == []
    assert sum(r.every for s in specs for r in stated_rules("taxi", s.description, "extended")) >= 20


@pytest.mark.parametrize("text, first", [
    ("First check whether the village has a long wait for passengers right now.", "long_wait"),
    ("So the taxi's first question is whether it's in the city.", "at_city"),
    ("Everything starts with the traffic on the city road. When it's heavy, think village.", "heavy_traffic"),
    ("Remember, the passenger comes first: if you have one, you go straight to the airport.", "has_passenger"),
    # a "first" inside a branch is not the root's, nor is a first stop
    ("Empty taxi: first see if it is at the airport.", None),
    ("I chose the village as the first stop because the road there is always clear.", None),
    ("With a passenger, drive to the airport.", None),
])
def test_the_question_a_text_says_to_ask_first(text, first):
    assert first_question("taxi", text) == first


@pytest.mark.parametrize("text, first", [
    ("First, check whether there is a car close in front, in the same lane.", "car_ahead_close"),
    ("The first thing it checks is whether it is in the rightmost lane.", "in_right_lane"),
    ("It starts by looking behind: if someone is tailgating, move right.", "car_behind_close"),
    # after the easy case, a "first" is inside the other branch
    ("If the road in front is clear, speed up. When it isn't, first try the left: if that lane is free, go left.", None),
    ("Its first priority is speed: it speeds up whenever the road in front is clear.", None),
])
def test_the_question_a_highway_text_says_to_ask_first(text, first):
    assert first_question("highway", text) == first


@pytest.mark.parametrize("domain, at_least", [("taxi", 50), ("highway", 35)])
def test_no_writers_tree_asks_another_question_first_than_its_description_says(domain, at_least):
    specs = load_corpus(domain)
    said = [(s, first_question(domain, s.description)) for s in specs]
    assert sum(q is not None for _, q in said) >= at_least
    assert [s.id for s, q in said if q is not None and q != getattr(s.tree, "question", None)] == []
