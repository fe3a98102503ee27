"""The actions a description names and the questions it asks, and the decoder's mention checks
that use them."""

import dataclasses

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.mentions import named_actions, named_questions, unasked_questions, unmet_mentions
from nl2policy.language.stated_rules import broken_rules
from nl2policy.language.models.config import MODELS
from nl2policy.language.train import fit
from nl2policy.trees import parse_tree
from nl2policy.trees.tree import questions_used
from test_language_train import _assert_teacher_forced


@pytest.mark.parametrize("text, actions", [
    ("Got a passenger: go to the airport. Not in the village? Drive to the city.", {"go_airport", "go_city"}),
    ("if traffic heavy -> village\nelse -> city", {"go_village", "go_city"}),
    ("wait in the city for a passenger", set()),  # the city is where it waits, not where it drives
    ("I'm the taxi, I like the village bakery.", set()),
])
def test_taxi_mentions(text, actions):
    assert named_actions("taxi", text) == actions


def test_highway_mentions_and_a_domain_without_patterns():
    assert named_actions("highway", "If blocked, move to the left lane; otherwise speed up.") == {"lane_left", "faster"}
    assert named_actions("highway", "Brake when a car is close ahead.") == {"slower"}
    assert named_actions("nowhere", "drive to the city") == set()


def test_unmet_mentions_are_the_named_actions_the_tree_never_takes():
    tree = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_village"}}, get_domain("taxi").vocab)
    text = "With a passenger, drive to the airport; without one, drive to the city."
    assert unmet_mentions("taxi", text, tree) == {"go_city"}
    assert unmet_mentions("taxi", "drive to the airport", tree) == set()


@pytest.mark.parametrize("domain, most", [("taxi", 1), ("highway", 3)])
def test_writers_trees_almost_always_take_every_action_their_text_names(domain, most):
    """The precision the mention check rests on (mentions.py's docstring): an action the patterns
    find is missing from the writer's own tree in at most 1 taxi and 3 highway descriptions of 200,
    while the patterns find something in nearly every description."""
    specs = load_corpus(domain)
    assert sum(bool(named_actions(domain, s.description)) for s in specs) >= 190
    assert sum(bool(unmet_mentions(domain, s.description, s.tree)) for s in specs) <= most


@pytest.mark.parametrize("attr, left_out", [("mention_cost", unmet_mentions), ("question_cost", unasked_questions),
                                            ("rule_cost", broken_rules)])
def test_each_check_never_leaves_more_of_what_the_text_names_out_and_keeps_the_probabilities(attr, left_out,
                                                                                           one_torch_thread):
    """A check (named actions, asked questions, stated rules) only changes which of the beam's final hypotheses
    is kept: with a prohibitive cost, no text ends with more of what it names left out than plain
    decoding leaves, some end with fewer (a small model ignores the text often enough), the node
    probabilities of a changed choice are that tree's own (teacher-forced), and the config's
    setting (none) gives plain decoding back."""
    specs = load_corpus("taxi")
    cfg = dataclasses.replace(MODELS["smoke"], epochs=2, batch=16, beam=4)
    model = fit("taxi", "one", cfg, [(s.description, s.tree) for s in specs[:40]], seed=0)
    texts = [s.description for s in specs[40:80]]
    missing = lambda decoded: [len(left_out("taxi", x, t)) for x, (t, _) in zip(texts, decoded)]
    plain = model.predict(texts)
    setattr(model, attr, 100.0)
    checked = model.predict(texts)
    assert all(c <= p for c, p in zip(missing(checked), missing(plain)))
    assert sum(missing(checked)) < sum(missing(plain))
    changed = [(x, c) for x, c, p in zip(texts, checked, plain) if c[0] != p[0]]
    assert changed
    for text, (tree, probs) in changed:
        _assert_teacher_forced(model, text, tree, probs)
    setattr(model, attr, None)
    assert model.predict(texts) == plain


@pytest.mark.parametrize("text, questions", [
    ("If it is already in the city, wait there; if not, drive to the city.", {"at_city"}),
    ("Sitting at the airport? Drive to the city.", {"at_airport"}),
    ("if inVillage:\n   if the wait is long: drive to city", {"at_village", "long_wait"}),
    ("First, check whether it has a passenger. No passenger: if the traffic is heavy, go to the village.",
     {"has_passenger", "heavy_traffic"}),
    ("if ur carrying someone drive to the airport", {"has_passenger"}),
    # places, waits and traffic named in passing, not asked about
    ("Drive to the city, where there are always passengers; the traffic plays no part.", set()),
    ("It waits in the city for a passenger, since the village can have a long wait.", set()),
])
def test_taxi_questions_a_text_asks(text, questions):
    assert named_questions("taxi", text) == questions


def test_unasked_questions_are_the_asked_questions_the_tree_never_asks():
    vocab = get_domain("taxi").vocab
    tree = parse_tree({"if": "has_passenger", "yes": {"do": "go_airport"}, "no": {"do": "go_city"}}, vocab)
    text = "With a passenger, drive to the airport. If you're already in the city, wait; if not, drive to the city."
    assert unasked_questions("taxi", text, tree) == {"at_city"}
    assert unasked_questions("taxi", "Got a passenger? Drive to the airport.", tree) == set()
    assert named_questions("highway", "If the left lane is free, move left.") == {"left_lane_free"}


@pytest.mark.parametrize("text, questions", [
    ("- At the airport: drive to the city\n- Anywhere other than the airport: wait", {"at_airport"}),
    ("a) in the village \u2192 leave for the city", {"at_village"}),
    ("So the only question is: are we in city now? If no, drive to city.", {"at_city"}),
    ("If it does, it checks whether it has reached the airport yet.", {"at_airport"}),
    ("if here == village:\n  wait\nelif parkedInCity: wait", {"at_village", "at_city"}),
    ("Passenger on board? Take them to the airport.", {"has_passenger"}),
    ("if gotRider: drive to airport\nelse: head to the city", {"has_passenger"}),
    ("in the village: w/ a passenger go to the airport", {"at_village", "has_passenger"}),
    ("a) city traffic heavy -> drive to the village\nb) traffic ok -> drive to the city", {"heavy_traffic"}),
    ("if cityRoadJammed then go to village", {"heavy_traffic"}),
    ("It looks at the traffic on the city road before it leaves.", {"heavy_traffic"}),
    ("Long waiting, drive to city. Not long, stay and wait.", {"long_wait"}),
    ("if villageWaitLong -> city anyway", {"long_wait"}),
    ("It considers how long the wait for a passenger is.", {"long_wait"}),
    # what the extended forms must still leave alone: actions, and things named in passing
    ("I don't look at traffic at all; in the village wait there for someone.", set()),
    ("The taxi in the village waits, since the village can have a long wait, and that is fine.", set()),
    ("Wait in the city for a passenger.", set()),
])
def test_taxi_questions_the_extended_forms_find(text, questions):
    assert named_questions("taxi", text, "extended") == questions
    assert named_questions("taxi", text) <= questions  # the conditions alone find no more


def test_unknown_question_forms_are_refused():
    with pytest.raises(ValueError, match="unknown question forms"):
        named_questions("taxi", "If it is in the city, wait.", "everything")


@pytest.mark.parametrize("text, questions", [
    ("If there is a car close in front, slow down; if the lane to the right is free, move right.",
     {"car_ahead_close", "right_lane_free"}),
    ("When someone is tailgating me, move over if I'm not in the rightmost lane.", {"car_behind_close", "in_right_lane"}),
    ("If the car is already driving fast, keep the lane.", {"going_fast"}),
    ("if it's in the leftmost lane, change right", {"in_left_lane"}),
    # actions, and reasons, are not conditions
    ("Keep right, speed up, and slow down if the left lane is blocked.", set()),
    ("Driving fast is rewarded, so it speeds up and stays behind nobody.", set()),
])
def test_highway_questions_a_text_asks(text, questions):
    assert named_questions("highway", text) == questions


@pytest.mark.parametrize("text, questions", [
    ("rightFree? -> change to the right lane\nnope ->\n    bumperAhead? -> slow down", {"right_lane_free", "car_ahead_close"}),
    ("tailgated, move right or speed up; car close ahead: slow down", {"car_behind_close", "car_ahead_close"}),
    ("car close ahead: go right if that's free, else slow down", {"car_ahead_close", "right_lane_free"}),
    ("if (inRightmost) { fast ? keep lane : speed up }", {"in_right_lane", "going_fast"}),
    ("if lane == leftmost then move right", {"in_left_lane"}),
    # reasons and goals, not conditions
    ("It speeds up when the left lane is blocked or it is already in the rightmost lane.", set()),
    ("The car is rewarded for going fast and for staying right; never tailgate.", set()),
])
def test_highway_questions_the_extended_forms_find(text, questions):
    assert named_questions("highway", text, "extended") == questions
    assert named_questions("highway", text) <= questions


@pytest.mark.parametrize("domain, forms, most_wrong, recall", [
    ("taxi", "conditions", 4, 0.7), ("taxi", "extended", 4, 0.9),
    ("highway", "conditions", 2, 0.65), ("highway", "extended", 2, 0.9),
])
def test_writers_trees_almost_always_ask_every_question_their_text_asks(domain, forms, most_wrong, recall):
    """The precision the question check rests on (mentions.py's docstring): a question the patterns
    find is missing from the writer's own tree in at most 4 of 200 taxi and 2 of 200 highway
    descriptions, while they find at least the given share of the questions the trees ask."""
    specs = load_corpus(domain)
    named = {s.id: named_questions(domain, s.description, forms) for s in specs}
    assert sum(bool(named[s.id] - questions_used(s.tree)) for s in specs) <= most_wrong
    asked = [(q, s) for s in specs for q in questions_used(s.tree)]
    assert sum(q in named[s.id] for q, s in asked) >= recall * len(asked)


def test_findings_are_cached_and_immutable():
    """The decoder and translate's warnings share one reading of a text (an LRU cache), so what
    a reading returns must not be changeable by either of them."""
    from nl2policy.language.stated_rules import stated_rules

    text = "If you are in the city with no passenger, wait. No passenger and not in the city: go to the city."
    questions = named_questions("taxi", text, "extended")
    assert isinstance(questions, frozenset) and named_questions("taxi", text, "extended") is questions
    assert isinstance(named_actions("taxi", text), frozenset)
    rules = stated_rules("taxi", text)
    assert isinstance(rules, tuple) and rules and stated_rules("taxi", text) is rules
    assert named_questions("taxi", text, "conditions") <= questions  # the forms are part of the key
