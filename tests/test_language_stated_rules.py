"""The rules a description states outright, and the trees that break them (stated_rules.py)."""

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.stated_rules import broken_rules, stated_rules
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
    assert stated_rules("highway", "If the left lane is free, move left.") == ()  # no patterns yet


def test_no_writers_tree_breaks_a_rule_its_description_states():
    """The precision the check and the warning rest on (stated_rules.py's docstring), while rules
    are found in most descriptions."""
    specs = load_corpus("taxi")
    assert sum(bool(stated_rules("taxi", s.description)) for s in specs) >= 120
    assert [s.id for s in specs if broken_rules("taxi", s.description, s.tree)] == []
