"""The synthetic generator's domain-free wording: filler, asides about what a tree leaves out,
summary lead-ins, and pseudo-code names made from a question's own id (`code_names`), so none
is a name a writer invented. Each domain's wording of its questions and actions is the domain's
own (domains/phrases/DOMAIN.toml, `Domain.phrases`).
"""

from __future__ import annotations

def code_names(question: str) -> list[str]:
    """Names a pseudo-code writer might give a question, made from its id alone:
    at_airport -> at_airport, atAirport, AtAirport, AT_AIRPORT, isAtAirport."""
    head, *rest = question.split("_")
    camel = head + "".join(part.title() for part in rest)
    pascal = camel[0].upper() + camel[1:]
    return [question, camel, pascal, question.upper(), "is" + pascal]


FILLER = [
    "Here's my plan.", "That's it, keep it simple.", "It's been raining all morning.", "I think this is a good plan.",
    "Repeat this all the time.", "Hope that makes sense!", "My cousin drives like this too.", "Anyway.",
    "I tried to keep it short.", "Good luck out there.",
]

ASIDES = [
    "I don't look at {q} at all.", "{Q} plays no part in this plan.", "I thought about {q} but left it out.",
    "I never bother checking {q}.", "I ignore {q} here.", "Forget about {q}, it doesn't matter.",
]
"""Sentences about a question the tree does *not* ask: long descriptions mention what was left out."""

UNUSED_ACTIONS = ["I never {a} in this plan.", "There's no reason to {a} here.", "It doesn't ever {a}."]

SUMMARIES = ["In short: ", "So to sum up: ", "To repeat it simply: ", "Basically: ", "Put simply, "]
"""Lead-ins to a second, compressed pass over the policy (explainers restate their plan)."""
