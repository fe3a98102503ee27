"""The actions a description names, found by patterns: "drive to the city", "-> airport",
"speed up", "move to the left lane"; and the questions it asks: "if it is in the city",
"whether it has a passenger", "if the wait there is long".

The
decoder's mention check (decoding.py) prefers, among its final hypotheses, a tree that does every
action the text names: a text that says "drive to the city" and a tree that never does are at odds.
The patterns are built for precision, not recall: on the corpus, an action they find is missing
from the writer's own tree in 1 of 197 taxi and 3 of 195 highway descriptions (tests check this),
while a tree's action they do not find is common (phrasings they do not know), so only the first
direction is used as evidence.

The question patterns serve the same check for the questions: a text that
asks "if it is already in the city" and a tree that never asks at_city are at odds. A question is
only seen where a condition asks it ("if/whether/when/unless/once ... in the city", "in the
city?", "not in the city", a code-style `inCity`), because descriptions also name places,
traffic and waits in passing ("the city always has passengers", "the traffic plays no part").
They were written reading the corpus, like the action patterns: a question they find is missing
from the writer's own tree in 4 of 200 taxi descriptions (a test checks this), and they find
about three in four of the questions the trees ask. The extended forms (`forms="extended"`) add
conditions written without a cue word: list items and headers ("- At the airport:", "Passenger on
board?", "city road heavy -> village", "long wait: city"), what the taxi checks ("it looks at the
traffic on the city road", "how long the wait is") and code (`if rider:`, `loc == airport`,
`villageWaitLong`). With them the patterns find 96% of the questions the trees ask, and a question
they find is still missing from the writer's tree in the same 4 of 200.

The highway patterns, written the same way, read a condition on the car ahead or behind ("if
there is a car close in front", "tailgated"), on a side lane ("if the left lane is free", "go right
if that's free"), on the outer lanes ("if it is in the rightmost lane") and on speed ("if it is
already driving fast"), and leave reasons alone ("rewarded for going fast", "or because it is
already in the rightmost lane"). On the corpus, a question they find is missing from the writer's
tree in none of the 200 highway descriptions, and they find 69% of the questions the trees ask by
the conditions, 96% with the extended forms (tests check these).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional

from nl2policy.trees import Tree
from nl2policy.trees.tree import iter_leaves, questions_used


@dataclass(frozen=True)
class ActionGroup:
    """Actions one pattern finds (and counterfactual copies may permute among themselves).
    `pattern` finds a mention; its group `key` is the part naming the action, `lookup` maps that
    part (lowercased) to the action, and `wording[action]` maps the mentioned form to how the
    other actions say it."""

    actions: tuple[str, ...]
    pattern: re.Pattern
    lookup: dict[str, str]
    wording: dict[str, dict[str, str]]  # action -> {mentioned form: replacement}, "*" for any form

    def rewrite(self, form: str, action: str) -> str:
        table = self.wording[action]
        return table.get(form.lower(), table.get("*", form))


_VERB = (r"(?:drive|drives|driving|go|goes|going|head|heads|heading|leave|leaves|return|returns|take|takes|"
         r"bring|move|moves|get|gets|back|straight|right|off|over|on|them|him|her|it|out|away|directly|"
         r"immediately|just|then|always)")
_TAXI = re.compile(
    rf"\b{_VERB}\s+(?:{_VERB}\s+){{0,3}}(?:to|for|towards|toward|into)\s+(?:the\s+)?(?P<key>airport|village|city)\b"
    rf"|(?:->|→|=>|:)\s*(?:go\s+|drive\s+|head\s+)?(?:to\s+)?(?:the\s+)?(?P<key2>airport|village|city)\b", re.I)

_SPEED_FORMS = {  # each form of "speed up" and its "slow down" counterpart, both ways
    "speed up": "slow down", "speeds up": "slows down", "speeding up": "slowing down",
    "accelerate": "brake", "accelerates": "brakes", "accelerating": "braking", "go faster": "go slower",
}
_SPEED_BACK = {v: k for k, v in _SPEED_FORMS.items()}
_SPEED_BACK.update({"decelerate": "accelerate", "decelerates": "accelerates"})
_SPEED = re.compile(r"\b(?P<key>" + "|".join(sorted(map(re.escape, list(_SPEED_FORMS) + list(_SPEED_BACK)),
                                                   key=len, reverse=True)) + r")\b", re.I)
LANE_MOVE = (r"\b(?:move|moves|moving|change|changes|changing|switch|switches|merge|merges|go|goes|shift|shifts|"
             r"pull|pulls|get|gets|steer|steers)\s+(?:over\s+|one\s+lane\s+|back\s+)?(?:(?:in)?to\s+)?(?:the\s+)?")
"""A lane change up to its side ("move over to the", "switch into the"): the side follows."""
_LANE = re.compile(LANE_MOVE + r"(?P<key>left|right)\b", re.I)

GROUPS: dict[str, list[ActionGroup]] = {
    "taxi": [ActionGroup(("go_airport", "go_village", "go_city"), _TAXI,
                         {"airport": "go_airport", "village": "go_village", "city": "go_city"},
                         {"go_airport": {"*": "airport"}, "go_village": {"*": "village"}, "go_city": {"*": "city"}})],
    "highway": [
        ActionGroup(("lane_left", "lane_right"), _LANE, {"left": "lane_left", "right": "lane_right"},
                    {"lane_left": {"*": "left"}, "lane_right": {"*": "right"}}),
        ActionGroup(("faster", "slower"), _SPEED,
                    {**{f: "faster" for f in _SPEED_FORMS}, **{f: "slower" for f in _SPEED_BACK}},
                    {"slower": dict(_SPEED_FORMS), "faster": dict(_SPEED_BACK)}),
    ],
}


def find_mentions(group: ActionGroup, text: str) -> list[tuple[int, int, str, str]]:
    """(start, end, mentioned form, action) of each action mention the group's pattern finds."""
    out = []
    for m in group.pattern.finditer(text):
        key = "key" if m.group("key") is not None else "key2"
        form = m.group(key)
        out.append((m.start(key), m.end(key), form, group.lookup[form.lower()]))
    return out


TEXTS_CACHED = 512
"""How many texts' findings are kept: the decoder's final choice and `translate`'s warnings read the
same text, so the patterns run once per description (a few tenths of a millisecond each)."""


@lru_cache(maxsize=TEXTS_CACHED)
def named_actions(domain: str, text: str) -> frozenset[str]:
    """The actions of `domain` that `text` is seen to name (empty for a domain without patterns)."""
    return frozenset(action for group in GROUPS.get(domain, []) for *_, action in find_mentions(group, text))


def unmet_mentions(domain: str, text: str, tree: Tree, named: Optional[frozenset[str]] = None) -> frozenset[str]:
    """Actions the text names that the tree never takes (`named`: named_actions(domain, text), if known)."""
    named = named_actions(domain, text) if named is None else named
    return frozenset(named) - {leaf.action for leaf in iter_leaves(tree)}


_CUE = r"(?:if|whether|when|whenever|unless|once)"
_SUBJECT = (r"(?:it|it's|its|it is|the taxi|the taxi's|the taxi is|the car|you|you're|you are|ur|u r|u|i|i'm|i am|"
            r"we|we're|we are|taxi|taxi is|taxi's|they|they're)")
_BE = r"(?:is|are|am|'s|already|currently|still|now|not|isn't|aren't|is not|are not|in fact|actually|sitting|parked|located|right)"


_NEAR_CUE = r"\b(?:if|whether|when|whenever|unless|once|while)\b[^.;:\n]{0,40}?"  # a cue, then the same clause


def _at(place: str) -> re.Pattern:
    """Where a condition asks whether the taxi is at `place`."""
    return re.compile(
        rf"\b{_CUE}\s+(?:{_SUBJECT}\s+)?(?:{_BE}\s+){{0,3}}(?:at|in)\s+(?:the\s+)?{place}\b"
        rf"|\b(?:in|at)\s+(?:the\s+)?{place}\?"
        rf"|\b(?:not|n't|isn't|aren't)\s+(?:at|in)\s+(?:the\s+)?{place}\b"
        rf"|\b(?:in|at)_?{place}\b(?=[^.]*:)|\b(?:in|at){place.capitalize()}\b|\bis(?:In|At){place.capitalize()}\b", re.I)


QUESTION_PATTERNS: dict[str, dict[str, re.Pattern]] = {
    "taxi": {
        "at_airport": _at("airport"), "at_village": _at("village"), "at_city": _at("city"),
        "has_passenger": re.compile(
            rf"\b{_CUE}\s+(?:{_SUBJECT}\s+)?(?:has|have|got|'s got|is carrying|are carrying|carrying|carries|does|do)\s+"
            r"(?:a\s+|any\s+|one\b|someone|somebody|anyone|anybody|nobody|no\s+)"
            r"|\b(?:no|without|with|got)\s+(?:a\s+)?passengers?\b(?!\s+(?:to|from|at|in)\b)"
            r"|\bempty\b|\bnobody in\b|\bsomeone in\b|\bpassenger in\b|\bhas_?passenger\b", re.I),
        "heavy_traffic": re.compile(
            rf"\b{_CUE}\b[^.;]{{0,50}}\b(?:heavy|light|jammed|congested|clear|busy)\b"
            r"|\btraffic\s+(?:on\s+the\s+(?:city\s+)?road\s+|to\s+(?:the\s+)?city\s+|there\s+)?(?:is|'s|are)\s+"
            r"(?:heavy|light|bad|clear)\b"
            r"|\b(?:heavy|light|no heavy)\s+traffic\b(?=[^.]*[,:])", re.I),
        "long_wait": re.compile(
            r"\bwait\s+(?:there\s+|at the village\s+|for (?:a )?passengers?\s+(?:there\s+)?)?"
            r"(?:is|'s|will be|is going to be|would be|looks)\s+(?:long|short)\b"
            rf"|\b{_CUE}\b[^.;]{{0,40}}\blong\s+wait\b|\blong_?wait\b", re.I),
    },
    # highway: what a condition (a cue word at most 40 characters before, in the same clause) says
    # about the car ahead or behind, a side lane's being free, the outer lanes, the car's speed
    "highway": {
        "car_ahead_close": re.compile(rf"{_NEAR_CUE}\b(?:ahead|in front|front)\b", re.I),
        "car_behind_close": re.compile(
            rf"{_NEAR_CUE}\b(?:(?:close|right|someone|somebody|anyone|anybody|nobody|no one|something|nothing|car|one)"
            r"\s+(?:is\s+)?(?:close\s+)?behind|tailgat(?:er|ers|ed|ing)|on (?:my|your|its|our|ur|the) tail)\b", re.I),
        "left_lane_free": re.compile(rf"{_NEAR_CUE}\bleft\b[^.;:\n]{{0,15}}\b(?:free|clear|open|empty|available)\b", re.I),
        "right_lane_free": re.compile(rf"{_NEAR_CUE}\bright\b[^.;:\n]{{0,15}}\b(?:free|clear|open|empty|available)\b", re.I),
        "in_left_lane": re.compile(rf"{_NEAR_CUE}\b(?:leftmost|left-most|far left)\b", re.I),
        "in_right_lane": re.compile(rf"{_NEAR_CUE}\b(?:rightmost|right-most|far right)\b", re.I),
        "going_fast": re.compile(rf"{_NEAR_CUE}\b(?:fast|slow(?!\s+down))\b", re.I),  # "slow down" is the action
    },
}


# list items and headers: "- At the airport:", "a) in the village ->", "In the city: ..."
_ITEM = r"(?:^|[\n:;.]|\b(?:and|but|so)\b)[ \t]*(?:[-*\u2022][ \t]*|\w\)[ \t]*|\d+[.)][ \t]*)?"
_ARROW = r"(?:->|\u2192)"


def _at_more(place: str) -> re.Pattern:
    """More ways to ask whether the taxi is at `place`: list headers, "am I at the airport?",
    "once it has reached the airport", "anywhere other than the airport", `loc == airport`."""
    return re.compile(
        rf"{_ITEM}(?:at|in)\s+(?:the\s+)?{place}\s*(?::|\?|{_ARROW})"
        rf"|\b(?:am|is|are)\s+{_SUBJECT}\s+(?:{_BE}\s+){{0,2}}(?:at|in)\s+(?:the\s+)?{place}\b"
        rf"|\b{_CUE}\b[^.;]{{0,30}}\b(?:reached|reaches|arrived at|arrives at|got to|gets to|"
        rf"find yourself (?:at|in))\s+(?:the\s+)?{place}\b"
        rf"|\b(?:other than|away from|outside(?: of)?)\s+the\s+{place}\b"
        rf"|\b(?:here|loc|location|spot|pos|position)\s*(?:==|is)\s*{place}\b"
        rf"|(?-i:\b[a-z]+(?:In|At){place.capitalize()}\b)", re.I)


def _free_side(side: str, other: str) -> re.Pattern:
    """Whether the lane on `side` is free, without a cue word before it: "left lane free ->",
    "right is clear", "go right if that's free", "the lane to my left is free", `leftLaneEmpty`."""
    return re.compile(
        rf"\b{side}\b(?:(?!\b{other}\b)[^.;\n]){{0,30}}?\b(?:if|when|whenever)\s+(?:it|that|that lane|that one|the lane|"
        r"its|it's|thats|that's|it is|that is)\s*(?:is\s+)?(?:free|clear|open|empty)\b"
        rf"|\blane\s+(?:to|on)\s+(?:the|my|your|its|our|ur)\s+{side}(?:\s+side)?\s+(?:is\s+|'s\s+)?(?:free|clear|open|empty)\b"
        rf"|\b{side}(?:\s+lane)?(?:'s|\s+is)?\s+(?:free|clear|open|empty)\b"
        rf"|(?-i:\b{side}(?:Lane)?(?:Free|Empty|Clear|Open)\b)", re.I)


def _outer_lane(side: str) -> re.Pattern:
    """Whether the car is in the outermost lane on `side`: "in the rightmost lane", "on the far
    right", `inRightmost`, "rightmost {", `lane == rightmost`; not "already in the rightmost lane",
    which the descriptions write as a reason the lane beside is not free."""
    most = f"{side}most"
    return re.compile(
        rf"(?<!already )(?<!being )\b(?:in|on)\s+(?:the\s+)?(?:{most}|{side}-most|far {side})\b"
        rf"|(?-i:\b(?:in)?{most.capitalize()}\b)|\b{most}\s*(?:\?|:|\{{|{_ARROW})|==\s*{most}", re.I)


# the "extended" forms, each added to a question's condition patterns above: the condition without
# a cue word ("Passenger on board?", "city road heavy -> village", "long wait: city"), what a taxi
# checks ("it checks the traffic on the city road", "how long the wait is"), and code (`if rider:`,
# `if cityRoadJammed`, `villageWaitLong`)
EXTENDED_QUESTION_PATTERNS: dict[str, dict[str, re.Pattern]] = {
    "taxi": {
        "at_airport": _at_more("airport"), "at_village": _at_more("village"), "at_city": _at_more("city"),
        "has_passenger": re.compile(
            r"\b(?:if|elif)\s+(?:\w*(?:rider|fare|passenger|loaded)\w*|someone|somebody|someone's)\b"
            r"|\b\w*(?:rider|fare|passenger)\w*\s*\?"
            r"|\b(?:passenger|someone|somebody|nobody|anyone|anybody|fare|rider)(?:'s)?\s+(?:is\s+)?"
            r"(?:on board|aboard|onboard|in the car|in the back|inside)\b"
            r"|\bw/\s*(?:a\s+)?(?:passenger|nobody|someone|no one)\b"
            rf"|\b{_CUE}\s+(?:a\s+)?(?:passenger|someone|somebody|anyone|anybody)\s+(?:has\s+)?(?:got|gets|is|has)\b"
            r"|\bcheck(?:s|ing)?\s+(?:for\s+)?(?:a\s+)?passengers?\b", re.I),
        "heavy_traffic": re.compile(
            r"\b(?:if|elif)\s+\w*(?:traffic|jam|road)\w*"
            r"|(?<!n't )(?<!not )(?<!never )\b(?:check|checks|checking|look|looks|looking|peek|peeks|depends on|based on|by)\s+(?:at\s+|on\s+)?"
            r"(?:the\s+)?(?:traffic|city road|road (?:to|into|toward) (?:the\s+)?city|city traffic)\b"
            r"|\b(?:city\s+road|road\s+(?:to|into|toward)\s+(?:the\s+)?city|city\s+traffic|"
            r"traffic\s+(?:to|toward|on)\s+(?:the\s+)?city(?:\s+road)?|road)\s+(?:is\s+|has\s+|have\s+)?(?:not\s+)?"
            r"(?:heavy|light|jammed|clear|clogged|ok|fine)\b"
            rf"|\b(?:heavy|light)\s+traffic\s*(?:\?|means|sends|{_ARROW})|\btraffic\s+(?:ok|fine|clear)\b", re.I),
        "long_wait": re.compile(
            r"(?<!in the )(?<!at the )(?<!in )(?<!at )\bvillage[ _]?wait(?!s\b)|\bthe\s+wait(?:ing)?(?:\s+time)?\s+(?:for\s+(?:a\s+|the\s+next\s+)?passengers?\s+)?"
            r"(?:at|in)\s+(?:the\s+)?village\b|\bwaiting\s+time\b|\bhow\s+long\s+(?:the\s+)?wait"
            r"|\bwait\s+(?:is|gets|be|isn't|is not)\s+(?:super\s+|too\s+|very\s+|not\s+)?(?:long|short)\b"
            rf"|(?<!a )\b(?:long|short)\s+wait(?:ing)?(?:\s+there)?\s*(?:[,:]|{_ARROW}|\b(?:expected|means|go|drive))", re.I),
    },
    # highway: the same without a cue word ("car close ahead: ...", "tailgated, move right",
    # "left lane free -> pass", "go right if that's free", "already fast"), and code (`bumperAhead`,
    # `rightFree`, `if (inRightmost)`, `lane == rightmost`); a reason is not a condition
    # ("rewarded for going fast", "or because it is already in the rightmost lane")
    "highway": {
        "car_ahead_close": re.compile(
            r"\b(?:close|near|right)\s+(?:in\s+front|ahead)\b|\bahead\s+close\b|(?-i:\b[a-z]\w*(?:Ahead|Front)\w*)"
            rf"|\b(?:car|someone|somebody|nobody|no one|anyone|something)\s+(?:close\s+)?(?:ahead|in front)\s*(?:\?|:|{_ARROW})",
            re.I),
        "car_behind_close": re.compile(
            r"\bclose\s+behind\b|\btailgat(?:er|ers|ed|ing)\b|\bon\s+(?:my|your|its|our|ur)\s+tail\b|(?-i:\b[a-z]\w*Behind\w*)",
            re.I),
        "left_lane_free": _free_side("left", "right"), "right_lane_free": _free_side("right", "left"),
        "in_left_lane": _outer_lane("left"), "in_right_lane": _outer_lane("right"),
        "going_fast": re.compile(
            r"(?<!for )(?<!and )\b(?:already|not|driving|going|is|am|i'm|it's|ur|you're|we're)\s+"
            r"(?:already\s+|driving\s+|going\s+)?fast\b(?!\s+(?:is|earns|pays|gets)\b)"
            rf"|\bfast\s*(?:\?|:|{_ARROW}|already)|\bif\s+fast\b|\bspeed\s+is\s+(?:fast|slow)\b", re.I),
    },
}

QUESTION_FORMS = ("conditions", "extended")  # which patterns named_questions uses


def named_questions(domain: str, text: str, forms: str = "conditions") -> frozenset[str]:
    """The questions of `domain` that `text` is seen to ask (empty for a domain without patterns):
    by the condition patterns alone, or with `forms="extended"` also by the extended forms."""
    if forms not in QUESTION_FORMS:
        raise ValueError(f"unknown question forms {forms!r}; choose one of {', '.join(QUESTION_FORMS)}")
    return _named_questions(domain, text, forms)


@lru_cache(maxsize=TEXTS_CACHED)
def _named_questions(domain: str, text: str, forms: str) -> frozenset[str]:
    tables = [QUESTION_PATTERNS] + ([EXTENDED_QUESTION_PATTERNS] if forms == "extended" else [])
    return frozenset(q for table in tables for q, pattern in table.get(domain, {}).items() if pattern.search(text))


def unasked_questions(domain: str, text: str, tree: Tree, named: Optional[frozenset[str]] = None,
                      forms: str = "conditions") -> frozenset[str]:
    """Questions the text asks that the tree never does (`named`: named_questions(domain, text, forms), if known)."""
    named = named_questions(domain, text, forms) if named is None else named
    return frozenset(named) - set(questions_used(tree))
