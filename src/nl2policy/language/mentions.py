"""The actions a description names, found by patterns: "drive to the city", "-> airport",
"speed up", "move to the left lane"; and the questions it asks: "if it is in the city",
"whether it has a passenger", "if the wait there is long".

Two uses. Counterfactual augmentation (counterfactual.py) rewrites the mentions it finds. The
decoder's mention check (train.py) prefers, among its final hypotheses, a tree that does every
action the text names: a text that says "drive to the city" and a tree that never does are at odds.
The patterns are built for precision, not recall: on the corpus, an action they find is missing
from the writer's own tree in 1 of 197 taxi and 3 of 195 highway descriptions (tests check this),
while a tree's action they do not find is common (phrasings they do not know), so only the first
direction is used as evidence.

The question patterns (taxi only, so far) serve the same check for the questions: a text that
asks "if it is already in the city" and a tree that never asks at_city are at odds. A question is
only seen where a condition asks it ("if/whether/when/unless/once ... in the city", "in the
city?", "not in the city", a code-style `inCity`), because descriptions also name places,
traffic and waits in passing ("the city always has passengers", "the traffic plays no part").
They were written reading the corpus, like the action patterns: a question they find is missing
from the writer's own tree in 4 of 200 taxi descriptions (a test checks this), and they find
about three in four of the questions the trees ask.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
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
_LANE = re.compile(r"\b(?:move|moves|moving|change|changes|changing|switch|switches|merge|merges|go|goes|shift|shifts|"
                   r"pull|pulls|get|gets|steer|steers)\s+(?:over\s+|one\s+lane\s+|back\s+)?(?:(?:in)?to\s+)?(?:the\s+)?"
                   r"(?P<key>left|right)\b", re.I)

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


def named_actions(domain: str, text: str) -> set[str]:
    """The actions of `domain` that `text` is seen to name (empty for a domain without patterns)."""
    return {action for group in GROUPS.get(domain, []) for *_, action in find_mentions(group, text)}


def unmet_mentions(domain: str, text: str, tree: Tree, named: Optional[set[str]] = None) -> set[str]:
    """Actions the text names that the tree never takes (`named`: named_actions(domain, text), if known)."""
    named = named_actions(domain, text) if named is None else named
    return named - {leaf.action for leaf in iter_leaves(tree)}


_CUE = r"(?:if|whether|when|whenever|unless|once)"
_SUBJECT = (r"(?:it|it's|its|it is|the taxi|the taxi's|the taxi is|the car|you|you're|you are|ur|u r|u|i|i'm|i am|"
            r"we|we're|we are|taxi|taxi is|taxi's|they|they're)")
_BE = r"(?:is|are|am|'s|already|currently|still|now|not|isn't|aren't|is not|are not|in fact|actually|sitting|parked|located|right)"


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
}


def named_questions(domain: str, text: str) -> set[str]:
    """The questions of `domain` that `text` is seen to ask (empty for a domain without patterns)."""
    return {q for q, pattern in QUESTION_PATTERNS.get(domain, {}).items() if pattern.search(text)}


def unasked_questions(domain: str, text: str, tree: Tree, named: Optional[set[str]] = None) -> set[str]:
    """Questions the text asks that the tree never does (`named`: named_questions(domain, text), if known)."""
    named = named_questions(domain, text) if named is None else named
    return named - set(questions_used(tree))
