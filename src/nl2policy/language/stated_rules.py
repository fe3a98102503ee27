"""The rules a description states outright: "No passenger and not in the village: go to the city",
"If it is heavy, it drives to the village", "a) in the village -> leave for the city". Each is a
condition (answers to some of the domain's questions) and the action the text gives under it.

Why: the beam's commonest remaining error is a leaf that follows the corpus's habit instead of
the text. "Not in the village" ends in go_village in most taxi trees, so a translator writes
go_village there even when the text says "not in the village: go to the city". The action check
(mentions.py) cannot see this when the tree drives to the city somewhere else.

A tree breaks a stated rule when no state of the world that meets the rule's condition gets the
rule's action from it. The test is existential on purpose: writers state rules in context ("If the
taxi is empty, it checks whether it is in the city. If it is in the city, it waits"), and the
context they leave out only narrows the states, so a rule that holds in context holds for some
state meeting the stated condition. A stricter reading (every such state) faults the writer's own
tree in 84 of the 200 taxi descriptions; this one faults none (a test checks this).

Only plain statements are read: within one sentence or clause (split at . ; ! ? and line
breaks), answers before exactly one action, nothing conditional after it ("..., unless",
"if not"), no "whether" before it (a question being asked, not answered) and no answer given both
ways. Like the mention patterns, the answer and action patterns were written reading the corpus
(the answers for taxi only), so cross-validation does not measure them on unread text.

The extended forms (`forms="extended"`) read two more ways of stating a rule:
- a quantified rule, "When it's clear, I drive to the city, no matter what", "Not in the city?
  Drive to the city, always": the writer says the action holds whatever else is true, so the
  rule is broken by any state meeting the condition that gets another action (the strict
  reading, which is wrong for unquantified rules, above). The quantifier must come before any
  reason the clause gives ("..., since the city always has people" quantifies the reason);
- an answered question, "Sitting at the airport? Drive to the city": a clause ending in "?" that
  names answers but no action is read with the clause after it on the same line, unless that one
  opens with its own condition ("If not, ...").
Quantifiers are also read as "with a passenger or without" (an answer given both ways on purpose)
and "anywhere else" is a place, not an "else" branch. On the taxi corpus they read 293 rules
against the plain forms' 269, 27 of them quantified, and still fault no writer's tree (a test
checks this), once waiting at a place counts as going there ("short wait means village, always").

The text may also say which question comes first ("First check whether the village has a long
wait", "the passenger comes first"): `first_question`, which the decoder's root cost reads. It is
read in highway too ("First, check whether there is a car close in front"), by highway's question
patterns (mentions.py) and action patterns; stated rules stay taxi only (no answer patterns).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional, Sequence

from nl2policy.domains import get_domain
from nl2policy.language.mentions import EXTENDED_QUESTION_PATTERNS, LANE_MOVE, QUESTION_PATTERNS, TEXTS_CACHED
from nl2policy.trees import Tree


@dataclass(frozen=True)
class StatedRule:
    """Under `condition` (question -> answer), the text says to take `action`; `text` is its clause."""

    condition: tuple[tuple[str, bool], ...]
    action: str
    text: str
    every: bool = False  # quantified ("always", "no matter what"): the action in every state meeting the condition


_NEG = r"(?:not|n't|isn't|aren't|never|no longer)"


def _place(place: str) -> list[tuple[str, bool, str]]:
    """Being at `place` or not. "wait in the city" and "in the city for a passenger" are actions."""
    return [(f"at_{place}", False, rf"\b{_NEG}\s+(?:already\s+|yet\s+)?(?:at|in)\s+(?:the\s+)?{place}\b"
                                   rf"|\b(?:outside(?: of)?|other than|away from)\s+the\s+{place}\b"),
            (f"at_{place}", True, r"(?<!not )(?<!n't )(?<!wait )(?<!waits )(?<!stay )(?<!stays )(?<!waiting )"
                                  rf"(?<!there )\b(?:at|in)\s+(?:the\s+)?{place}\b(?!\s+for)")]


# (question, answer, pattern) for taxi. Where a "no" and a "yes" of one question overlap
# ("does not have a passenger"), the "no" wins.
_ANSWERS: dict[str, list[tuple[str, bool, str]]] = {"taxi": [
    ("has_passenger", False, r"\b(?:not|n't)\s+(?:have|has|carry|carrying|got)\s+(?:a\s+|any\s+)?(?:passenger|rider|fare)s?\b"
                             r"|\bno\s+(?:passenger|one|rider|fare)s?\b|\bwithout\s+(?:a\s+|one\b|any|passengers?\b)"
                             r"|\bempty\b|\bnobody\b|\bw/\s*nobody\b"),
    ("has_passenger", True, r"(?<!for )(?<!no )(?<!without )\b(?:a\s+|the\s+|any\s+)?passengers?\b"
                            r"(?!\s+(?:to|from|come|comes|show|shows|get|gets|turn|turns))"
                            r"|\bsomeone(?:'s)?\s+(?:is\s+)?(?:in|on|aboard)\b|\bwith\s+(?:a\s+|one\b)"
                            r"|\bw/\s*(?:a\s+)?passenger|\bgot\s+(?:someone|a\s+passenger|one\b)"),
    ("heavy_traffic", False, r"\b(?:light|clear|not heavy|isn't heavy|no heavy|no jam|fine|ok)\b(?![^.;,]*\bwait)"),
    ("heavy_traffic", True, r"(?<!not )(?<!no )\b(?:heavy|jammed|congested|clogged)\b"),
    ("long_wait", False, r"\b(?:short|not long|isn't long|isnt long|is not long)\b"),
    ("long_wait", True, r"(?<!not )(?<!isn't )(?<!isnt )\blong\b(?=[^.;]{0,25}\bwait)"
                        r"|\bwait\b[^.;,]{0,25}(?<!not )(?<!isn't )\blong\b"),
] + _place("airport") + _place("village") + _place("city")}


def _goes(place: str) -> str:
    """Driving to `place`: "to the city", "leave for the city", "-> city", "means the city"."""
    return (rf"(?<!road )(?<!traffic )(?:to|toward|towards|for)\s+(?:the\s+)?{place}\b"
            rf"|(?:->|\u2192|:)\s*(?:the\s+)?{place}\b|\bmeans\s+(?:the\s+)?{place}\b")


_ACTIONS: dict[str, list[tuple[str, str]]] = {"taxi": [
    ("go_airport", _goes("airport")), ("go_village", _goes("village")), ("go_city", _goes("city")),
    ("wait", r"(?<!long )(?<!short )(?<!the )(?<!a )\b(?:wait|waits|stay|stays|stay put|wait it out)\b"
             r"(?!\s+(?:is|for a passenger at the village|there is|gets|be|at the village is))"),
], "highway": [  # read by first_question only (highway has no answer patterns, so no stated rules)
    ("lane_left", LANE_MOVE + r"left\b"), ("lane_right", LANE_MOVE + r"right\b"),
    ("faster", r"\b(?:speed(?:s|ing)?\s+up|accelerat\w*|go(?:es)?\s+faster)\b"),
    ("slower", r"\b(?:slow(?:s|ing)?\s+down|brak(?:e|es|ing)|decelerat\w*|go(?:es)?\s+slower)\b"),
    ("idle", r"\b(?:keep|keeps|keeping|hold|holds|stay|stays)\s+(?:in\s+)?(?:its|my|the|your|our|ur|same|current)?\s*"
             r"(?:lane|speed)\b|\bcruise\b"),
]}
_CLAUSE = re.compile(r"[.;!?\n]+")
_CLAUSE_KEEP = re.compile(r"([.;!?\n]+)")  # the same split, keeping what split it
RULE_FORMS = ("plain", "extended")  # which statements stated_rules reads
_QUANTIFIER = re.compile(r"\b(?:always|(?:no|doesn't|does not|don't|dont) matter (?:what|where|how)|either way|regardless"
                         r"|whatever happens|in any case"
                         r"|every time|any ?time|whenever|wherever\b[^,;]*|whoever\b[^,;]*)\b", re.I)
_BOTH_WAYS = re.compile(r"\bwith(?:\s+a|\s+one)?\s+(?:passenger|rider|fare|someone)s?,?\s+or\s+without(?:\s+one)?\b", re.I)
"""An answer given both ways on purpose ("with passenger or without, it drives to the city"): a quantifier."""
_ELSEWHERE = re.compile(r"\b(?:anywhere|everywhere|somewhere)\s+else\b", re.I)  # a place, not an "else" branch
_REASON = re.compile(r"\b(?:since|because|b/c|cause|as|where|so that|rather than|that's|thats|there's|theres|there is"
                     r"|there are)\b", re.I)
_OWN_CONDITION = re.compile(r"\s*(?:if|when|unless|otherwise|else|no|not|nope|yes)\b", re.I)
_CONDITIONAL_AFTER = re.compile(r"\b(?:if|unless|otherwise|else|except|whether|when|but)\b", re.I)
_ASKED_BEFORE = re.compile(r"\b(?:whether|unless|otherwise|else|except)\b", re.I)


def _answers(domain: str, clause: str) -> list[tuple[int, int, str, bool]]:
    found = [(m.start(), m.end(), q, a) for q, a, p in _ANSWERS.get(domain, []) for m in re.finditer(p, clause, re.I)]
    noes = [(s, e, q) for s, e, q, a in found if not a]
    return [(s, e, q, a) for s, e, q, a in found
            if not a or not any(q == q2 and s < e2 and s2 < e for s2, e2, q2 in noes)]


def stated_rules(domain: str, text: str, forms: str = "plain") -> tuple[StatedRule, ...]:
    """The rules `text` states outright, in order (empty for a domain without patterns): plain
    statements, or with `forms="extended"` also quantified rules and answered questions."""
    if forms not in RULE_FORMS:
        raise ValueError(f"unknown rule forms {forms!r}; choose one of {', '.join(RULE_FORMS)}")
    return _stated_rules(domain, text, forms)


def _clauses(domain: str, text: str, forms: str) -> list[str]:
    """The clauses rules are read from; with the extended forms, an answered question ("At the
    airport? Drive to the city") joined into one."""
    if forms == "plain":
        return _CLAUSE.split(text)
    parts = _CLAUSE_KEEP.split(text)
    clauses, i = [], 0
    while i < len(parts):
        clause, sep = parts[i], parts[i + 1] if i + 1 < len(parts) else ""
        after = parts[i + 2] if i + 2 < len(parts) else ""
        if sep.strip(" ") == "?" and _answers(domain, clause) and not _actions(domain, clause) \
                and _actions(domain, after) and not _OWN_CONDITION.match(after):
            clauses.append(f"{clause}? {after.strip()}")
            i += 4
        else:
            clauses.append(clause)
            i += 2
    return clauses


def _actions(domain: str, clause: str) -> list[tuple[int, int, str]]:
    return sorted((m.start(), m.end(), a) for a, p in _ACTIONS[domain] for m in re.finditer(p, clause, re.I))


def _quantified(clause: str) -> bool:
    """Whether the clause quantifies its rule: a quantifier before any reason it gives."""
    reason = _REASON.search(clause)
    return bool(_QUANTIFIER.search(clause[:reason.start()] if reason else clause))


@lru_cache(maxsize=TEXTS_CACHED)  # the decoder's final choice and translate's warnings read the same text
def _stated_rules(domain: str, text: str, forms: str) -> tuple[StatedRule, ...]:
    if domain not in _ANSWERS:
        return ()
    possible = get_domain(domain).possible_answer_sets
    rules = []
    for clause in _clauses(domain, text, forms):
        actions = _actions(domain, clause)
        if not actions or len({a for *_, a in actions}) > 1:
            continue
        start, end, action = actions[0]
        said = clause.strip()
        both_ways = forms == "extended" and _BOTH_WAYS.search(clause[:start])
        if both_ways:  # not a condition: read the clause without it
            clause = clause[:both_ways.start()] + " " * len(both_ways.group()) + clause[both_ways.end():]
        answers = _answers(domain, clause)
        if any(s >= end for s, *_ in answers) or _CONDITIONAL_AFTER.search(clause[end:]) \
                or _ASKED_BEFORE.search(_ELSEWHERE.sub("", clause[:start]) if forms == "extended" else clause[:start]):
            continue
        condition: dict[str, bool] = {}
        for s, e, q, a in answers:
            if e <= start:
                if condition.get(q, a) != a:
                    break  # answered both ways: not a plain statement
                condition[q] = a
        else:
            if condition and any(all(state[q] == a for q, a in condition.items()) for state in possible):
                rules.append(StatedRule(tuple(sorted(condition.items())), action, said,
                                        forms == "extended" and bool(both_ways or _quantified(clause))))
    return tuple(rules)


def broken_rules(domain: str, text: str, tree: Tree, rules: Optional[Sequence[StatedRule]] = None,
                 forms: str = "plain") -> list[StatedRule]:
    """The stated rules (`rules`: stated_rules(domain, text, forms), if known) that `tree` breaks:
    no state meeting the condition gets the action, or, for a quantified rule, some such state
    gets another."""
    rules = stated_rules(domain, text, forms) if rules is None else rules
    possible = get_domain(domain).possible_answer_sets
    broken = []
    for r in rules:
        states = [state for state in possible if all(state[q] == a for q, a in r.condition)]
        if all(tree.act(state) != r.action for state in states) \
                or (r.every and not all(_same_act(domain, state, tree.act(state), r.action) for state in states)):
            broken.append(r)
    return broken


def _same_act(domain: str, state: dict[str, bool], act: str, said: str) -> bool:
    """Whether `act` does what `said` asks in `state`: in taxi, waiting at a place is going there
    ("short wait means the village, always" holds for the taxi that waits in the village)."""
    if act == said:
        return True
    return domain == "taxi" and act == "wait" and said.startswith("go_") and state.get(f"at_{said[3:]}", False)


_FIRST = re.compile(r"\b(?:first(?:\s+of\s+all)?(?!\s+(?:stop|place|choice|priority|destination|trip|time)\b)"
                    r"|to\s+start|start(?:s|ing)?\s+(?:by|with|w/)|begin(?:s|ning)?\s+(?:by|with)|before\s+anything\s+else)\b", re.I)
_COMES_FIRST = re.compile(r"\b(?:comes?|goes?)\s+first\b", re.I)
_SENTENCE = re.compile(r"[.;!?\n]")


# what a question is about, named bare after "first" or "starts with" ("Everything starts with the
# traffic on the city road"): only read there, and before any action
_TOPICS: dict[str, list[tuple[str, str]]] = {"taxi": [
    ("heavy_traffic", r"\b(?:traffic|city road|road (?:to|into|toward) (?:the\s+)?city|jam)\b"),
    ("long_wait", r"\b(?:village wait|wait(?:ing)?(?: time)? (?:in|at|for) the village|how long (?:the )?wait|the wait)\b"),
    ("has_passenger", r"\b(?:passengers?|rider|fare|someone in the car|back seat)\b"),
]}


def _asked(domain: str, text: str, topics: bool = False) -> list[tuple[int, str]]:
    """(position, question) of each question `text` asks or answers before any action it names
    (with `topics`, also each it is about: _TOPICS)."""
    found = [(s, q) for s, _, q, _ in _answers(domain, text)]
    for table in (QUESTION_PATTERNS, EXTENDED_QUESTION_PATTERNS):
        found += [(m.start(), q) for q, p in table.get(domain, {}).items() for m in [p.search(text)] if m]
    if topics:
        found += [(m.start(), q) for q, p in _TOPICS.get(domain, []) for m in [re.search(p, text, re.I)] if m]
    action = min((s for s, _, _ in _actions(domain, text)), default=len(text))
    return [(s, q) for s, q in found if s < action]


_FIRST_BEFORE_ANY_QUESTION = {"highway"}
"""Domains where a "first" names the root only before the text has asked any question."""


@lru_cache(maxsize=TEXTS_CACHED)
def first_question(domain: str, text: str) -> Optional[str]:
    """The question the text says to ask first, if it says so: "First check whether the village has
    a long wait", "So the taxi's first question is whether it's in the city", "Everything starts
    with the traffic on the city road", "the passenger comes first" (None for a domain without
    patterns). A "first" inside a branch is not the root's ("Empty taxi: first see if it is at the
    airport"), so the sentence must name no question before its "first". A highway description
    often gives the easy case before the rest ("If the road in front is clear, speed up. When there
    is a car, ... First try the left"), so there a "first" after any question the text has already
    asked is inside a branch too. No writer's tree asks another question first (0 of 200 taxi and 0
    of 200 highway descriptions; a test checks this)."""
    if domain not in _ACTIONS:
        return None
    start = 0
    for sentence in _SENTENCE.split(text):
        if domain in _FIRST_BEFORE_ANY_QUESTION and _asked(domain, text[:start]):
            return None
        start += len(sentence) + 1  # the one character split on
        comes_first = _COMES_FIRST.search(sentence)
        if comes_first and (before := _asked(domain, sentence[:comes_first.start()], topics=True)):
            return max(before)[1]
        cue = _FIRST.search(sentence)
        if cue and not _asked(domain, sentence[:cue.start()]) \
                and (after := _asked(domain, sentence[cue.end():], topics=True)):
            return min(after)[1]
    return None
