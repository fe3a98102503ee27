"""Asking when unsure: questions about situations, and answers that hold decoding to them.

A person who describes a policy may not be able to check a nested tree, but always knows what
the robot should do in one situation. So where the translation is unsure, the translator asks
about the situation whose answer is expected to remove the most of its doubt: among the trees
the model finds plausible (a wide grammar-constrained beam, each tree weighed by its score), the
situation where they disagree most (1 - sum of squared action shares). Answers that agree
with the tree first shown leave it as it is (a confirmed tree is no reason to redraw it);
otherwise the tree is decoded anew with every answer a constraint of decoding itself
(`allow_for`): no tree that acts otherwise in an answered situation is ever built, so every tree
returned after an answer acts as answered, and trees outside the first beam can come back.
After each answer the tree's confidence is its probability given the answers (`posterior`), and
the translator asks again only while that is still below the threshold it first asked under.

A situation names an answer to every question of the domain's dictionary, and only
combinations the domain allows (one taxi location; no free lane beyond the edge of the road):
the `possible_answer_sets` of the domain spec. Its words come from the domain's own phrases,
leaving out what the other facts already imply.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence

from nl2policy.domains import get_domain
from nl2policy.errors import UserError
from nl2policy.language.decoding import Allow, Hypothesis, tree_probability
from nl2policy.language.grammar import Slot
from nl2policy.trees import Tree

ASK_BELOW = 0.6
"""Confidence under which the translator asks: at 0.6 and above, translations of new writers'
new trees were right 98 of 99 times (the reliability measured for the translator issue), so a
question there would rarely change anything."""
CANDIDATES = 32
"""Hypotheses of the wide beam whose disagreement chooses the question."""
MIN_SPLIT = 0.01
"""Expected share of the candidates' weight an answer must be able to remove to be worth asking."""
MAX_QUESTIONS = 3
"""Questions asked about one description by default."""


class BadAnswer(UserError, ValueError):
    """An answer that cannot be used: the message says which and why."""


class NoTreeFits(UserError, ValueError):
    """No valid tree acts as every answer says."""


Situation = tuple[tuple[str, bool], ...]
"""A situation as a hashable, ordered value: (question, answer) in the dictionary's order."""


@dataclass(frozen=True)
class Answer:
    situation: Situation
    do: str

    def to_json(self) -> dict:
        return {"situation": dict(self.situation), "do": self.do}


@dataclass(frozen=True)
class Question:
    situation: Situation
    text: str
    choices: tuple[tuple[str, str], ...]  # (action id, its words)

    def to_json(self) -> dict:
        return {"situation": dict(self.situation), "text": self.text,
                "choices": [{"do": a, "text": words} for a, words in self.choices]}


def situations(domain: str) -> list[Situation]:
    """Every situation the domain allows, in a fixed order."""
    d = get_domain(domain)
    return [tuple((q, bool(a[q])) for q in d.vocab.question_ids) for a in d.possible_answer_sets]


def situation_text(domain: str, situation: Situation) -> str:
    """ "The taxi is at the village, the taxi is empty, ... What should it do?": one plain
    statement per fact (the first wording of each in the domain's phrases), without the facts
    the others imply (at the village: so not at the airport nor in the city)."""
    d = get_domain(domain)
    facts = dict(situation)
    shown = dict(facts)
    for q, v in sorted(facts.items(), key=lambda kv: kv[1]):  # drop implied "no"s first
        rest = {k: x for k, x in shown.items() if k != q}
        if d.forced_answer(rest, q) == v:
            shown = rest
    words = [d.phrases["questions"][q]["pos" if v else "neg"][0] for q, v in shown.items()]
    listed = words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]
    return f"{listed[:1].upper()}{listed[1:]}. What should it do?"


def question_for(domain: str, situation: Situation) -> Question:
    actions = get_domain(domain).vocab.actions
    return Question(situation, situation_text(domain, situation), tuple(actions.items()))


def parse_answers(domain: str, raw: Sequence[Any], max_questions: int = MAX_QUESTIONS) -> list[Answer]:
    """Answers from JSON-like values ({"situation": {question: bool}, "do": action}), checked:
    known questions and actions, every question answered, a situation the domain allows, no
    situation answered twice, no more answers than questions may be asked."""
    d = get_domain(domain)
    if len(raw) > max_questions:
        raise BadAnswer(f"{len(raw)} answers given, but at most {max_questions} questions are asked")
    allowed = set(situations(domain))
    out: list[Answer] = []
    for i, item in enumerate(raw, 1):
        where = f"answer {i}"
        if not isinstance(item, Mapping) or set(item) != {"situation", "do"}:
            raise BadAnswer(f'{where}: expected {{"situation": {{question: true/false, ...}}, "do": ACTION}}')
        situation, do = item["situation"], item["do"]
        if not isinstance(do, str) or do not in d.vocab.actions:
            raise BadAnswer(f"{where}: unknown action {str(do)[:40]!r}; choose one of {', '.join(d.vocab.action_ids)}")
        if not isinstance(situation, Mapping):
            raise BadAnswer(f"{where}: the situation must map each question to true or false")
        unknown = sorted(str(q)[:40] for q in situation if q not in d.vocab.questions)
        if unknown:
            raise BadAnswer(f"{where}: unknown question {unknown[0]!r}")
        missing = [q for q in d.vocab.question_ids if q not in situation]
        if missing:
            raise BadAnswer(f"{where}: the situation does not answer {', '.join(missing)}; a situation answers every question")
        if not all(isinstance(v, bool) for v in situation.values()):
            raise BadAnswer(f"{where}: every answer in a situation is true or false")
        key = tuple((q, situation[q]) for q in d.vocab.question_ids)
        if key not in allowed:
            raise BadAnswer(f"{where}: the {domain} domain never has this situation (e.g. two places at once, or a free "
                            "lane beyond the edge of the road)")
        earlier = next((a for a in out if a.situation == key), None)
        if earlier is not None:
            word = "contradicts" if earlier.do != do else "repeats"
            raise BadAnswer(f"{where} {word} an earlier answer about the same situation")
        out.append(Answer(key, do))
    return out


def path_answers(slot: Slot) -> list[tuple[str, bool]]:
    """The (question, answer) pairs that lead from the root to `slot` (its grid position says
    which branch each step took: odd = yes)."""
    branches, g = [], slot.grid
    while g > 0:
        branches.append(g % 2 == 1)
        g = (g - 1) // 2
    return list(zip(slot.path, reversed(branches)))


def allow_for(domain: str, answers: Sequence[Answer]) -> Optional[Allow]:
    """The decoding restriction of `answers`: a slot that an answered situation reaches may hold
    a question (the situation goes on down one branch) or that answer's action, nothing else."""
    if not answers:
        return None
    questions = tuple(get_domain(domain).vocab.question_ids)

    def allow(prefix: tuple[str, ...], slot: Slot) -> Optional[frozenset[str]]:
        steps = path_answers(slot)
        needed = {a.do for a in answers if all(dict(a.situation)[q] == v for q, v in steps)}
        if not needed:
            return None
        return frozenset(questions + tuple(needed)) if len(needed) == 1 else frozenset(questions)

    return allow


def agrees(tree: Tree, answers: Sequence[Answer]) -> bool:
    return all(tree.act(dict(a.situation)) == a.do for a in answers)


def weights(hypotheses: Sequence[Hypothesis]) -> list[float]:
    """Each hypothesis's share of the beam's weight (its score, a log-probability, normalized)."""
    top = max(h[2] for h in hypotheses)
    raw = [math.exp(h[2] - top) for h in hypotheses]
    total = sum(raw)
    return [r / total for r in raw]


def posterior(tree: Tree, p_tree: float, held: Sequence[Hypothesis], wide: Sequence[Hypothesis],
              answers: Sequence[Answer]) -> float:
    """How likely `tree` (of model probability `p_tree`) is the one meant, once `answers` hold:
    Bayes' rule, its probability over that of every tree that acts as answered. That sum is what
    the two beams hold of it (`held`: decoded under the answers; `wide`: decoded without them),
    plus the probability neither beam reached, counted at the rate at which the wide beam's trees
    act as answered. Without answers it is `p_tree` itself, the calibrated confidence; a
    confirming answer raises it as much as it rules alternatives out."""
    prob = {h[0]: tree_probability(h[1]) for h in [*wide, *held] if h[0] is not None}
    fits = {t for t in prob if agrees(t, answers)}
    seen = {h[0] for h in wide if h[0] is not None}
    in_wide = sum(prob[t] for t in seen)
    rate = sum(prob[t] for t in seen & fits) / in_wide if in_wide > 0 else 1.0
    unseen = max(0.0, 1.0 - sum(prob.values()))
    return min(1.0, prob.get(tree, p_tree) / max(sum(prob[t] for t in fits) + unseen * rate, 1e-12))


def best_question(domain: str, hypotheses: Sequence[Hypothesis], answered: Sequence[Answer]) -> Optional[Situation]:
    """The situation whose answer is expected to remove the most of the candidates' weight
    (1 - sum over actions of their share squared), among those not yet answered; None when no
    situation splits them by at least MIN_SPLIT."""
    cands = [(h[0], w) for h, w in zip(hypotheses, weights(hypotheses)) if h[0] is not None]
    done = {a.situation for a in answered}
    best, best_split = None, MIN_SPLIT
    for situation in situations(domain):
        if situation in done:
            continue
        facts = dict(situation)
        share: dict[str, float] = {}
        for tree, w in cands:
            action = tree.act(facts)
            share[action] = share.get(action, 0.0) + w
        split = 1.0 - sum(p * p for p in share.values())
        if split > best_split + 1e-12:
            best, best_split = situation, split
    return best
