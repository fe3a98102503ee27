"""A domain's declarative spec: vocabulary wording from the corpus, plus what each question
tests on the policy's input features.

Every question is one linear test ``w . x > c`` on the feature vector. That single fact is
what lets a lexical tree become a differentiable decision tree that acts exactly like it
(the DDT node is ``sigmoid(gamma * (w . x - c))``).

The spec also holds the domain's *knobs* (``Knobs``: DDT sharpness, leaf mass, PPO settings,
evaluation episodes, ...), each with the reason for its value beside it in the TOML, so that
the policy code reads one typed record instead of dicts keyed by domain name; and, where the
domain has one, an *exact model* (``Domain.exact``) that scores a policy without sampling.
"""

from __future__ import annotations

import dataclasses
import importlib
import itertools
import json
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Protocol, Sequence

import numpy as np

from nl2policy.data import corpus_dir
from nl2policy.trees import Leaf, Tree, Vocabulary

SPEC_DIR = Path(__file__).resolve().parent


@dataclass(frozen=True)
class PPOSettings:
    """Stable-Baselines3 PPO arguments, the same for every method of a domain."""

    n_steps: int
    batch_size: int
    n_epochs: int
    gamma: float  # the discount (not the DDT's sharpness)
    learning_rate: float
    ent_coef: float = 0.0  # SB3's default

    def as_kwargs(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Knobs:
    """How a domain's trees become DDTs, are trained and are judged. Override one for an
    experiment with ``dataclasses.replace(domain.knobs, leaf_mass=0.9)`` and pass it down."""

    ddt_gamma: float  # DDT node sharpness: sigmoid(ddt_gamma * (w . x - c))
    leaf_mass: float  # a fresh leaf's probability on the tree's action
    match_tolerance: float  # how near a learned threshold must be to a question's to be named by it
    actor_lr_scale: float  # the DDT actor's learning rate as a multiple of PPO's
    ppo: PPOSettings
    eval_episodes: int  # episodes for every sampled before/after return of a tree or DDT
    rolling_window: int  # episodes in the rolling mean of training reward
    fidelity_gammas: tuple[float, ...]  # other sharpnesses in the fidelity report's sensitivity rows
    train_envs: int = 1  # episodes side by side when training on the domain's fast vector env
    select_episodes: Optional[int] = None  # fast-env episodes for keep-best's sampled score of a tree
    polish_screen_episodes: Optional[int] = None  # fast-env episodes a sampled polish screens each neighbour on


Act = Callable[[np.ndarray], int]


class ExactModel(Protocol):
    """A domain's exact model: expectations without sampling noise."""

    def expected_return(self, act: Act) -> float:
        """The exact expected episode return of a policy that sees the features."""

    def expected_returns(self, acts: list[Act]) -> list[float]:
        """``expected_return`` of many policies (searches score thousands)."""

    def expected_return_mixed(self, action_probs: Callable[[np.ndarray], np.ndarray]) -> float:
        """The exact expected return of a stochastic policy: `action_probs` maps feature
        vectors (n, features) to action probabilities (n, actions)."""

    def optimum(self) -> float:
        """The best expected return of any policy (the ceiling)."""


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
    knobs: Knobs
    exact_model: Optional[str] = None  # "module:factory" of an ExactModel, or None
    train_env_id: Optional[str] = None  # a registered vector env (vector entry point) that trains faster than env_id
    one_hot: tuple[str, ...] = ()  # features of which exactly one is 1 (taxi's place); see uniform_states
    title: str = ""  # how people see the domain named (the app's domain menu)
    example: str = ""  # the description `nl2policy run` translates when given none
    briefing_section: Optional[str] = None  # the corpus briefing's "## <section>" about this domain

    @cached_property
    def phrases(self) -> dict[str, dict]:
        """How the synthetic generator words this domain (phrases/NAME.toml): `questions` (per id:
        pos, neg, short, short_no), `actions` and `reasons` (per id: lists of wordings)."""
        return tomllib.loads((SPEC_DIR / "phrases" / f"{self.name}.toml").read_text())

    @cached_property
    def exact(self) -> Optional[ExactModel]:
        """The exact model where the domain has one (taxi), else None (highway): what lets
        the policy code score a tree without sampling, asked for as a capability."""
        if self.exact_model is None:
            return None
        module, factory = self.exact_model.split(":")
        return getattr(importlib.import_module(module), factory)()

    def uniform_states(self, n: int, seed: int = 0) -> np.ndarray:
        """`n` feature vectors spread evenly over what the world can produce: with a one-hot
        group (taxi), one of its features set uniformly and every other feature 0 or 1;
        otherwise uniform in the [0, 1] feature box (highway; far more mass near thresholds
        than real traffic puts there)."""
        rng = np.random.default_rng(seed)
        if not self.one_hot:
            return rng.uniform(0.0, 1.0, size=(n, len(self.features))).astype(np.float32)
        group = np.eye(len(self.one_hot))[rng.integers(len(self.one_hot), size=n)]
        rest = [f for f in self.features if f not in self.one_hot]
        bits = rng.integers(2, size=(n, len(rest)))
        columns = {**dict(zip(self.one_hot, group.T)), **dict(zip(rest, bits.T))}
        return np.stack([columns[f] for f in self.features], axis=1).astype(np.float32)

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
    one_hot = tuple(spec.get("one_hot", ()))
    if set(one_hot) - set(features):
        raise ValueError(f"{spec_path.name}: one_hot names unknown features {sorted(set(one_hot) - set(features))}")
    return Domain(name, vocab, tuple(features), weights, thresholds, impossible, spec["env_id"],
                  _knobs(spec, spec_path.name), exact_model=spec.get("exact_model"), one_hot=one_hot,
                  train_env_id=spec.get("train_env_id"), title=spec.get("title", name.capitalize()),
                  example=spec.get("example", ""), briefing_section=spec.get("briefing_section"))


def _knobs(spec: dict, file: str) -> Knobs:
    """The [knobs] table, every field required and no unknown key, so that a typo in the TOML
    is an error rather than a silent default."""

    def typed(cls, table: dict, where: str):
        names = {f.name: f for f in dataclasses.fields(cls)}
        required = {n for n, f in names.items() if f.default is dataclasses.MISSING}
        unknown, missing = set(table) - set(names), required - set(table)
        if unknown or missing:
            raise ValueError(f"{file}: [{where}] unknown keys {sorted(unknown)}, missing keys {sorted(missing)}")
        return table

    table = dict(typed(Knobs, spec.get("knobs", {}), "knobs"))
    table["ppo"] = PPOSettings(**typed(PPOSettings, table["ppo"], "knobs.ppo"))
    table["fidelity_gammas"] = tuple(float(g) for g in table["fidelity_gammas"])
    for key in ("ddt_gamma", "leaf_mass", "match_tolerance", "actor_lr_scale"):
        table[key] = float(table[key])
    return Knobs(**table)
