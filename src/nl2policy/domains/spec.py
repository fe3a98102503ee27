"""A domain's declarative spec: vocabulary wording from the corpus, plus what each question
tests on the policy's input features.

Every question is one linear test ``w . x > c`` on the feature vector. That single fact is
what lets a lexical tree become a differentiable decision tree that acts exactly like it
(the DDT node is ``sigmoid(gamma * (w . x - c))``).
"""

from __future__ import annotations

import itertools
import json
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nl2policy.data import corpus_dir
from nl2policy.trees import Leaf, Tree, Vocabulary

SPEC_DIR = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Domain:
    """Everything about a domain that is not the simulator itself."""

    name: str
    vocab: Vocabulary
    features: tuple[str, ...]
    weights: np.ndarray = field(repr=False)  # (questions, features), rows in vocab order
    thresholds: np.ndarray = field(repr=False)  # (questions,)
    impossible: tuple[Mapping[str, bool], ...]
    env_id: str

    @property
    def questions(self) -> list[str]:
        return self.vocab.question_ids

    @property
    def actions(self) -> list[str]:
        return self.vocab.action_ids

    def answer_matrix(self, x: np.ndarray) -> np.ndarray:
        """Answers (bool) to every question for a batch of feature vectors, shape (n, questions)."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        return x @ self.weights.T > self.thresholds

    def answers(self, x: np.ndarray) -> dict[str, bool]:
        """Answers for one feature vector, keyed by question id."""
        row = self.answer_matrix(x)[0]
        return dict(zip(self.questions, map(bool, row)))

    def action_index(self, action: str) -> int:
        return self.actions.index(action)

    def tree_action(self, tree: Tree, x: np.ndarray) -> int:
        """The action index a lexical tree picks for feature vector `x`."""
        return self.action_index(tree.act(self.answers(x)))

    def tree_actions(self, tree: Tree, x: np.ndarray) -> np.ndarray:
        """The action index a lexical tree picks for each row of a batch of feature vectors."""
        answers = self.answer_matrix(x)

        def act(node: Tree) -> np.ndarray:
            if isinstance(node, Leaf):
                return np.full(len(answers), self.action_index(node.action), dtype=np.int64)
            return np.where(answers[:, self.questions.index(node.question)], act(node.yes), act(node.no))

        return act(tree)

    def is_possible(self, answers: Mapping[str, bool]) -> bool:
        return not any(all(answers[q] == v for q, v in rule.items()) for rule in self.impossible)

    @cached_property
    def possible_answer_sets(self) -> list[dict[str, bool]]:
        """Every combination of answers the world can produce: the cases two policies must
        agree on to count as the same policy."""
        combos = (dict(zip(self.questions, bits)) for bits in itertools.product((False, True), repeat=len(self.questions)))
        return [a for a in combos if self.is_possible(a)]

    def forced_answer(self, answered: Mapping[str, bool], question: str) -> bool | None:
        """The one answer `question` can have where the answers in `answered` hold, or None if
        both can: under "at the airport? yes", "at the village?" is always no. A tree that asks
        it there has a branch no state reaches."""
        seen = {a[question] for a in self.possible_answer_sets if all(a[q] == v for q, v in answered.items())}
        return seen.pop() if len(seen) == 1 else None

    def same_policy(self, a: Tree, b: Tree) -> bool:
        return all(a.act(ans) == b.act(ans) for ans in self.possible_answer_sets)


def load_domain(name: str, corpus: Path | None = None) -> Domain:
    spec_path = SPEC_DIR / f"{name}.toml"
    if not spec_path.is_file():
        known = sorted(p.stem for p in SPEC_DIR.glob("*.toml"))
        raise KeyError(f"unknown domain {name!r}; known domains: {', '.join(known)}")
    spec = tomllib.loads(spec_path.read_text())
    vocabulary = json.loads(((corpus or corpus_dir()) / "vocabulary.json").read_text())
    if name not in vocabulary:
        raise KeyError(f"the corpus vocabulary has no domain {name!r}")
    vocab = Vocabulary(name, dict(vocabulary[name]["questions"]), dict(vocabulary[name]["actions"]))
    features: Sequence[str] = spec["features"]
    tests = spec["tests"]
    missing = set(vocab.questions) ^ set(tests)
    if missing:
        raise ValueError(f"{spec_path.name}: questions and tests differ on {sorted(missing)}")
    weights = np.zeros((len(vocab.questions), len(features)))
    thresholds = np.zeros(len(vocab.questions))
    for i, q in enumerate(vocab.questions):
        for feat, w in tests[q]["weights"].items():
            weights[i, features.index(feat)] = w
        thresholds[i] = tests[q]["threshold"]
    impossible = tuple(dict(rule) for rule in spec.get("impossible", []))
    return Domain(name, vocab, tuple(features), weights, thresholds, impossible, spec["env_id"])
