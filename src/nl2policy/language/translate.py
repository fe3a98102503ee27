"""The translator as a product: load (or first train) a domain's default model, translate one
description into a valid tree with a confidence and warnings.

A description that is empty raises `EmptyDescription`; one that is off-topic or about the
other domain still gets a (valid) tree, but with a low confidence and a warning saying why,
so no caller mistakes it for a confident answer. Where the tree and the text's learned findings
(language/findings.py, the same reading decoding weighs) disagree, a warning says where: an
action the text seems to take, or a question it seems to ask, that the tree never uses; a
question the tree asks that the text does not seem to; another question first than the one the
text seems to ask first.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import torch

from nl2policy.domains import get_domain
from nl2policy.language.clarify import (ASK_BELOW, CANDIDATES, MAX_QUESTIONS, Answer, BadAnswer, NoTreeFits, Question,
                                        agrees, allow_for, best_question, parse_answers, posterior,
                                        question_for)
from nl2policy.language.decoding import Hypothesis, tree_probability
from nl2policy.language.findings import Findings, FindingsModel, root_label
from nl2policy.language.models.config import DEFAULT_MODEL, ModelConfig
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.text import tokenize
from nl2policy.language.translator import TrainedTranslator
from nl2policy.trees import Tree, tree_to_json
from nl2policy.trees.tree import iter_leaves, questions_used

LOW_CONFIDENCE = 0.5
FINDING = 0.5
"""A finding counts for the warnings where its probability is at least this (the classifier's own
decision threshold: no value fitted to descriptions)."""
STOPWORDS = set("the a an to of and or if is it in on at for be i you my your we this that there not no yes then".split())


class EmptyDescription(ValueError):
    """The description has no words to translate."""


@dataclass
class Translation:
    tree: Tree
    confidence: float
    warnings: list[str] = field(default_factory=list)
    node_confidence: dict[int, float] = field(default_factory=dict)  # grid slot -> probability
    questions: list[Question] = field(default_factory=list)  # what to ask the user next (clarify.py)

    def to_json(self) -> dict:
        return {"tree": tree_to_json(self.tree), "confidence": round(self.confidence, 4), "warnings": list(self.warnings),
                "questions": [q.to_json() for q in self.questions]}


def shipped_path(domain: str, name: str = DEFAULT_MODEL) -> Path:
    """Where a domain's shipped translator lies: in its folder, as translator-<version>.pt
    (domains/README.md has the command that trained it)."""
    return get_domain(domain).folder / f"translator-{name}.pt"


def model_dir() -> Path:
    """The user's models: $NL2POLICY_HOME/models (default: the platform's user data dir)."""
    from nl2policy.paths import home

    return home() / "models"


def model_path(domain: str, name: str = DEFAULT_MODEL, folder: Optional[Path] = None) -> Path:
    """A model's file in `folder` (default: the user's models): DOMAIN-VERSION.pt, except in the
    domain's own folder, where it is the shipped translator-VERSION.pt."""
    folder = folder or model_dir()
    if folder.resolve() == get_domain(domain).folder.resolve():
        return shipped_path(domain, name)
    return folder / f"{domain}-{name}.pt"


def find_model(domain: str, name: str = DEFAULT_MODEL) -> Optional[Path]:
    """The user's trained model if there is one, else the shipped one, else None. A data folder
    that cannot be made has no user models: the shipped one still translates."""
    try:
        paths = [model_path(domain, name, model_dir()), shipped_path(domain, name)]
    except OSError:
        paths = [shipped_path(domain, name)]
    return next((path for path in paths if path.is_file()), None)


@dataclass
class LoadedModel:
    translator: TrainedTranslator
    lexicon: dict[str, set[str]]


def load_model(path: Path, domain: Optional[str] = None) -> LoadedModel:
    """The translator in `path`, for `domain` (default: the one it was trained for; a copied
    domain folder translates with its original's file under its own name)."""
    data = torch.load(path, weights_only=False)
    known = {f.name for f in fields(ModelConfig)}
    cfg = ModelConfig(**{k: v for k, v in data["cfg"].items() if k in known})  # (settings of deleted variants: off)
    states = data["nets"] if "nets" in data else [data["net"]]  # "net": files from before ensembles
    translator = TrainedTranslator.from_states(domain or data["domain"], data["name"], cfg, data["words"], states,
                                               MiniLMCache(max_items=256))
    if data.get("findings") is not None:
        translator.findings = FindingsModel.from_state(data["findings"], translator.cache)
    lexicon = {d: set(ws) for d, ws in data["lexicon"].items()}
    if domain and domain != data["domain"] and data["domain"] in lexicon:  # a copied folder: its words are the original's
        lexicon[domain] = lexicon.pop(data["domain"])
    return LoadedModel(translator, lexicon)


_LOADED: dict[tuple[str, str], LoadedModel] = {}


def get_model(domain: str, name: str = DEFAULT_MODEL) -> LoadedModel:
    """The saved default model, training it first (progress on stderr) when there is none."""
    key = (domain, name)
    if key not in _LOADED:
        path = find_model(domain, name)
        if path is None:
            path = model_path(domain, name)
            print(f"No trained {name} translator for {domain} in {path.parent} or {get_domain(domain).folder}; "
                  "training it now (a few minutes)...",
                  file=sys.stderr)
            last = [-1]

            def report(done: int, total: int) -> None:
                pct = 100 * done // total
                if pct // 10 != last[0]:
                    last[0] = pct // 10
                    print(f"  training {domain} translator: {pct}%", file=sys.stderr)

            from nl2policy.language import shipping  # the training stack, only when there is no model to load

            # members train in forked processes, unless other threads run here (a server):
            # a fork copies only this thread, and a lock another one holds stays locked
            shipping.train_default(domain, name, progress=report, workers=1 if threading.active_count() > 1 else None)
        _LOADED[key] = load_model(path, domain)
    return _LOADED[key]


def check_topic(domain: str, text: str, lexicon: dict[str, set[str]]) -> tuple[float, list[str]]:
    """(factor to scale confidence by, warnings) from the domain words the text uses."""
    words = tokenize(text)
    hits = {d: sum(w in lex for w in words) for d, lex in lexicon.items()}
    own = hits.get(domain, 0)
    other, other_hits = max(((d, h) for d, h in hits.items() if d != domain), key=lambda x: x[1], default=(None, 0))
    if own == 0 and other_hits == 0:
        return 0.05, [f"off-topic: nothing in the description is about the {domain} domain"]
    if other_hits > own:
        return 0.1, [f"this reads like a description for the {other} domain, not {domain}"]
    return 1.0, []


def _asks(domain: str, question: str) -> str:
    """A question's words for a warning: the dictionary's, without its note ("Is the lane to my
    left free? (no: there is a car there, or no lane)" -> "is the lane to my left free")."""
    return get_domain(domain).vocab.questions[question].split("?")[0].lower()


def translate(domain: str, text: str, name: str = DEFAULT_MODEL, answers: Sequence[Any] = (),
              max_questions: int = MAX_QUESTIONS) -> Translation:
    """Translate one description into a valid tree of `domain`, with confidence, warnings and,
    where it is unsure, a question about a situation (clarify.py). `answers` are the user's
    answers to the questions asked so far, in order ({"situation": ..., "do": ACTION}): the tree
    returned acts as each says. Raises EmptyDescription, BadAnswer (an unknown action, a situation
    the domain forbids or that was not asked, a contradiction) or NoTreeFits."""
    get_domain(domain)
    if not isinstance(text, str) or not tokenize(text):
        raise EmptyDescription("the description is empty: write what the policy should do")
    parsed = parse_answers(domain, answers, max_questions)
    return translate_with(get_model(domain, name), domain, text, parsed, max_questions)


def translate_with(loaded: LoadedModel, domain: str, text: str, answers: Sequence[Answer] = (),
                   max_questions: int = MAX_QUESTIONS, check_asked: bool = True) -> Translation:
    """`translate` with a loaded model and checked answers. `check_asked`: replay the questions
    and refuse an answer to a situation that was not the one asked at its turn (a caller that
    asked them itself, like the simulated user, may skip it)."""
    found = loaded.translator.read_findings([text])  # read once: decoding weighs it, the warnings quote it
    factor, warnings = check_topic(domain, text, loaded.lexicon) if loaded.lexicon else (1.0, [])
    plain = loaded.translator.predict([text], found=found)[0]  # the same for every step of the replay
    wide = _Wide(loaded.translator, text, found[0] if found else None)
    if check_asked:
        for i, answer in enumerate(answers):
            asked = _step(loaded, domain, text, found, plain, wide, answers[:i], factor, max_questions)[3]
            if asked is None or asked.situation != answer.situation:
                raise BadAnswer(f"answer {i + 1} is about a situation that was not asked "
                                + ("(nothing was asked there)" if asked is None else f"(the question was: {asked.text})"))
    tree, node_probs, confidence, question = _step(loaded, domain, text, found, plain, wide, answers, factor,
                                                   max_questions)
    if confidence < LOW_CONFIDENCE:
        warnings.append(f"low confidence ({confidence:.2f}): check the tree before using it")
    if found is not None and factor == 1.0:  # off-topic text: its findings mean nothing
        warnings += disagreements(domain, tree, found[0])
    return Translation(tree, confidence, warnings, {k: v * factor for k, v in node_probs.items()},
                       [question] if question else [])


class _Wide:
    """The wide beam without answers, decoded at most once per translation (each step of a replay
    may need it)."""

    def __init__(self, model: TrainedTranslator, text: str, own: Optional[Findings]) -> None:
        self.model, self.text, self.own = model, text, own
        self.beam: Optional[list[Hypothesis]] = None

    def __call__(self) -> list[Hypothesis]:
        if self.beam is None:
            self.beam = self.model.hypotheses(self.text, self.own, None, width=CANDIDATES)
        return self.beam


def _step(loaded: LoadedModel, domain: str, text: str, found: Optional[list[Findings]],
          plain: tuple[Tree, dict[int, float]], wide: _Wide, answers: Sequence[Answer], factor: float,
          max_questions: int) -> tuple[Tree, dict[int, float], float, Optional[Question]]:
    """The tree, its node probabilities, its confidence and the next question, given answers.
    Without answers this is the plain translation (`plain`: the model's beam; confidence = the
    tree's probability). With answers, the plain translation stands while it acts as every answer
    says (an answer that confirms the tree is no reason to redraw it); otherwise the tree is the
    best of a wide beam held to the answers. Its confidence is then its probability given the
    answers (clarify.posterior), so one threshold decides, before and after answers, whether to ask."""
    model, own = loaded.translator, found[0] if found else None
    first, first_probs = plain
    tree, node_probs = first, first_probs
    confidence = tree_probability(first_probs) * factor
    candidates = None
    if answers:
        candidates = model.hypotheses(text, own, allow_for(domain, answers), width=CANDIDATES)
        if candidates[0][0] is None:
            raise NoTreeFits("no tree of at most 3 questions on a path acts as all the answers say; "
                             "check the answers, or edit the tree by hand")
        if not agrees(first, answers):
            tree, node_probs, _ = candidates[0]
        confidence = posterior(tree, tree_probability(node_probs), candidates, wide(), answers) * factor
    question = None
    if confidence < ASK_BELOW and len(answers) < max_questions and factor == 1.0:
        situation = best_question(domain, candidates or wide(), answers)
        question = question_for(domain, situation) if situation is not None else None
    return tree, node_probs, max(0.0, min(1.0, confidence)), question


def disagreements(domain: str, tree: Tree, found: Findings) -> list[str]:
    """Warnings for each place the tree and the text's findings disagree, most likely first in kind:
    what the text seems to say that the tree leaves out, what the tree asks that the text does not
    seem to, and the root."""
    actions = get_domain(domain).vocab.actions
    asked, taken = questions_used(tree), {leaf.action for leaf in iter_leaves(tree)}
    out = []
    for action, p in sorted(found.takes.items(), key=lambda kv: -kv[1]):
        if p >= FINDING and action not in taken:
            out.append(f"the description seems ({p:.0%}) to say to {actions[action].lower()} ({action}), but the tree "
                       "never does: check where it should")
    for question, p in sorted(found.asks.items(), key=lambda kv: -kv[1]):
        if p >= FINDING and question not in asked:
            out.append(f"the description seems ({p:.0%}) to ask \"{_asks(domain, question)}?\" ({question}), but the "
                       "tree never does: check where it should")
    for question in sorted(asked, key=lambda q: found.asks[q]):
        if found.asks[question] < FINDING:
            out.append(f"the tree asks \"{_asks(domain, question)}?\" ({question}), which the description does not "
                       f"seem ({found.asks[question]:.0%}) to ask: check that branch")
    first, p = max(found.root.items(), key=lambda kv: kv[1])
    if p >= FINDING and first != root_label(tree) and first in found.asks:
        out.append(f"the description seems ({p:.0%}) to ask first \"{_asks(domain, first)}?\" ({first}), but the tree "
                   "asks something else first: check its top")
    return out
