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
(taxi only so far), so cross-validation does not measure them on unread text.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional, Sequence

from nl2policy.domains import get_domain
from nl2policy.language.mentions import TEXTS_CACHED
from nl2policy.trees import Tree


@dataclass(frozen=True)
class StatedRule:
    """Under `condition` (question -> answer), the text says to take `action`; `text` is its clause."""

    condition: tuple[tuple[str, bool], ...]
    action: str
    text: str


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
]}
_CLAUSE = re.compile(r"[.;!?\n]+")
_CONDITIONAL_AFTER = re.compile(r"\b(?:if|unless|otherwise|else|except|whether|when|but)\b", re.I)
_ASKED_BEFORE = re.compile(r"\b(?:whether|unless|otherwise|else|except)\b", re.I)


def _answers(domain: str, clause: str) -> list[tuple[int, int, str, bool]]:
    found = [(m.start(), m.end(), q, a) for q, a, p in _ANSWERS[domain] for m in re.finditer(p, clause, re.I)]
    noes = [(s, e, q) for s, e, q, a in found if not a]
    return [(s, e, q, a) for s, e, q, a in found
            if not a or not any(q == q2 and s < e2 and s2 < e for s2, e2, q2 in noes)]


@lru_cache(maxsize=TEXTS_CACHED)  # the decoder's final choice and translate's warnings read the same text
def stated_rules(domain: str, text: str) -> tuple[StatedRule, ...]:
    """The rules `text` states outright, in order (empty for a domain without patterns)."""
    if domain not in _ANSWERS:
        return ()
    possible = get_domain(domain).possible_answer_sets
    rules = []
    for clause in _CLAUSE.split(text):
        actions = sorted((m.start(), m.end(), a) for a, p in _ACTIONS[domain] for m in re.finditer(p, clause, re.I))
        if not actions or len({a for *_, a in actions}) > 1:
            continue
        start, end, action = actions[0]
        answers = _answers(domain, clause)
        if any(s >= end for s, *_ in answers) or _CONDITIONAL_AFTER.search(clause[end:]) \
                or _ASKED_BEFORE.search(clause[:start]):
            continue
        condition: dict[str, bool] = {}
        for s, e, q, a in answers:
            if e <= start:
                if condition.get(q, a) != a:
                    break  # answered both ways: not a plain statement
                condition[q] = a
        else:
            if condition and any(all(state[q] == a for q, a in condition.items()) for state in possible):
                rules.append(StatedRule(tuple(sorted(condition.items())), action, clause.strip()))
    return tuple(rules)


def broken_rules(domain: str, text: str, tree: Tree, rules: Optional[Sequence[StatedRule]] = None) -> list[StatedRule]:
    """The stated rules (`rules`: stated_rules(domain, text), if known) that no state meeting their
    condition gets their action for from `tree`."""
    rules = stated_rules(domain, text) if rules is None else rules
    possible = get_domain(domain).possible_answer_sets
    return [r for r in rules
            if all(tree.act(state) != r.action for state in possible if all(state[q] == a for q, a in r.condition))]
