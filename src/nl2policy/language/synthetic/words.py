"""The words a synthetic description is made of: the domain's own phrases for its questions and
actions (domains/DOMAIN/phrases.toml), and general English (english.toml) for everything around
them, drawn with one random generator so a pair is reproducible from its seed."""

from __future__ import annotations

import random
import tomllib
from functools import lru_cache
from pathlib import Path
from typing import Sequence

from nl2policy.domains import get_domain

ENGLISH_FILE = Path(__file__).with_name("english.toml")


@lru_cache(maxsize=1)
def english() -> dict:
    """The general lexicon (english.toml)."""
    return tomllib.loads(ENGLISH_FILE.read_text())


def code_names(question: str) -> list[str]:
    """Names a pseudo-code writer might give a question, made from its id alone:
    at_airport -> at_airport, atAirport, AtAirport, AT_AIRPORT, isAtAirport."""
    head, *rest = question.split("_")
    camel = head + "".join(part.title() for part in rest)
    pascal = camel[0].upper() + camel[1:]
    return [question, camel, pascal, question.upper(), "is" + pascal]


class Words:
    """Phrase picker for one description: `pos`/`neg` statements true on a question's yes/no
    branch, `short` forms, the dictionary's own question, action phrases in a frame, and
    `en(key)` for a general-English entry."""

    def __init__(self, domain: str, rng: random.Random, formal: bool = False) -> None:
        d = get_domain(domain)
        phrases = d.phrases
        self.q, self.a, self.why = phrases["questions"], phrases["actions"], phrases["reasons"]
        self.agents = phrases.get("agent", {}).get("names", ["it"])
        self.asked = d.vocab.questions
        self.rng, self.formal = rng, formal
        self.correct = 0.0  # chance that an action is said with a spoken self-correction
        self.agent = self.pick(self.agents)  # one description keeps one name for its robot

    def pick(self, options: Sequence) -> str:
        return self.rng.choice(list(options))

    def chance(self, p: float) -> bool:
        return self.rng.random() < p

    def en(self, key: str) -> str:
        return self.pick(english()[key])

    # ---- questions ---------------------------------------------------------------------------
    def pos(self, q: str) -> str:
        return self.pick(self.q[q]["pos"])

    def neg(self, q: str) -> str:
        if self.chance(0.12):  # any statement can be negated in general words
            return self.en("not_case").format(s=self.pos(q))
        return self.pick(self.q[q]["neg"])

    def cond(self, q: str, yes: bool) -> str:
        return self.pos(q) if yes else self.neg(q)

    def short(self, q: str, yes: bool = True) -> str:
        return self.pick(self.q[q]["short" if yes else "short_no"])

    def question(self, q: str) -> str:
        """The dictionary's question ("Is the taxi at the airport?"), without its note."""
        text = self.asked[q]
        return text.split(" (")[0] if "(" in text else text

    def code(self, q: str) -> str:
        return self.pick(code_names(q))

    # ---- actions ----------------------------------------------------------------------------
    def act(self, a: str) -> str:
        """A bare imperative phrase ("drive to the airport")."""
        return self.pick(self.a[a])

    def act_said(self, a: str, why: float = 0.2, correct: float = 0.0) -> str:
        """An action as a clause: in a frame ("the taxi should ..."), sometimes with a reason or
        a spoken self-correction that names another action first."""
        frame = self.en("act_formal") if self.formal and self.chance(0.7) else self.en("act_frames")
        phrase = self.act(a)
        if correct and self.chance(correct):
            other = self.pick([x for x in self.a if x != a])
            phrase = f"{self.act(other)}, {self.en('corrections')} {phrase}"
        text = frame.format(a=phrase, agent=self.agent)
        if self.chance(why):
            text += self.en("because") + self.pick(self.why[a])
        return text

    def cap(self, text: str) -> str:
        return text[:1].upper() + text[1:] if text else text
