"""A domain's declarative spec (``domains/<name>/spec.toml``): its dictionary of questions and
actions, what each question tests on the policy's input features, its environment, and its knobs.

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

from nl2policy.trees import FeatureUnit, Leaf, Node, Tree, TreeError, Vocabulary, parse_raw, parse_tree


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
    leaf_temperature_end: float = 1.0  # DDT leaf softmax temperature at the end of training, annealed from 1
    leaf_temperature_from: float = 0.0  # fraction of the run after which that line starts (before it: 1)
    node_sharpness_end: float = 1.0  # multiple of ddt_gamma at the end of training, on a line from 1
    node_sharpness_from: float = 0.0  # fraction of the run after which that line starts (before it: 1)
    learn_node_features: bool = True  # False: a tree-initialized DDT's node weights get no gradient; thresholds and leaves learn
    critic_reading: bool = False  # True: checkpoints also read the tree PPO's critic favours (advantage.py)
    adopt_read_tree: bool = False  # True: where a reading beats the DDT's rounding, PPO continues from it

    def __post_init__(self) -> None:
        if not (self.leaf_temperature_end > 0 and self.node_sharpness_end > 0 and 0 <= self.node_sharpness_from < 1
                and 0 <= self.leaf_temperature_from < 1):
            raise ValueError("knobs: leaf_temperature_end and node_sharpness_end must be > 0, node_sharpness_from and "
                             f"leaf_temperature_from in [0, 1); got {self.leaf_temperature_end}, {self.node_sharpness_end}, "
                             f"{self.node_sharpness_from}, {self.leaf_temperature_from}")


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

    name: str  # the folder's name
    folder: Path  # domains/<name>/: spec.toml, phrases.toml, the env's code, the shipped translator
    package: str  # the folder as a Python package, where the spec's "module:attribute" entries are found
    vocab: Vocabulary
    features: tuple[str, ...]
    weights: np.ndarray = field(repr=False)  # (questions, features), rows in vocab order
    thresholds: np.ndarray = field(repr=False)  # (questions,)
    impossible: tuple[Mapping[str, bool], ...]
    env_id: str
    knobs: Knobs
    exact_model: Optional[str] = None  # "module:factory" of an ExactModel in the folder, or None
    train_env_id: Optional[str] = None  # a registered vector env (vector entry point) that trains faster than env_id
    one_hot: tuple[str, ...] = ()  # features of which exactly one is 1 (taxi's place); see uniform_states
    translator: Mapping[str, Any] = field(default_factory=dict)  # recipe settings this domain's shipped translator changes
    ranges: tuple[tuple[float, float], ...] = ()  # per feature, the box uniform_states spreads over (default [0, 1])
    title: str = ""  # how people see the domain named (the app's domain menu)
    example: str = ""  # the description `nl2policy run` translates when given none
    example_tree: Optional[Tree] = None  # the tree `example` says: a test checks the shipped translator reads it so,
    # and a domain no one has described starts Table 2's tree-DDT runs from it (a tree a person would write)
    briefing_section: Optional[str] = None  # the corpus briefing's "## <section>" about this domain
    ceilings: Optional[str] = None  # a module in the folder with compute_ceilings / write_ceilings (nl2policy ceilings)
    reference: Optional[str] = None  # "module:function" in the folder: a hand-written policy of features to actions, a yardstick

    @cached_property
    def phrases(self) -> dict[str, dict]:
        """How the synthetic generator words this domain (its phrases.toml): `questions` (per id:
        pos, neg, short, short_no), `actions` and `reasons` (per id: lists of wordings)."""
        return tomllib.loads((self.folder / "phrases.toml").read_text())

    def module(self, name: str) -> Any:
        """The module `name` of this folder (a spec entry such as `ceilings`)."""
        return importlib.import_module(f"{self.package}.{name}")

    def attribute(self, entry: str) -> Any:
        """The object a spec entry "module:attribute" names, the module found in this folder."""
        module, _, attr = entry.partition(":")
        return getattr(self.module(module), attr)

    def feature_box(self, i: int) -> tuple[float, float]:
        """(low, high) of feature `i`: the spec's [ranges], else [0, 1]."""
        return self.ranges[i] if self.ranges else (0.0, 1.0)

    @cached_property
    def exact(self) -> Optional[ExactModel]:
        """The exact model where the domain has one (taxi), else None (highway): what lets
        the policy code score a tree without sampling, asked for as a capability."""
        if self.exact_model is None:
            return None
        return self.attribute(self.exact_model)()

    def uniform_states(self, n: int, seed: int = 0) -> np.ndarray:
        """`n` feature vectors spread evenly over what the world can produce: with a one-hot
        group (taxi), one of its features set uniformly and every other feature 0 or 1;
        otherwise uniform in the feature box, [0, 1] or the spec's [ranges] (highway, lunar; far
        more mass near thresholds than the world puts there)."""
        rng = np.random.default_rng(seed)
        if not self.one_hot:
            lo, hi = np.array([self.feature_box(i) for i in range(len(self.features))]).T
            return (lo + (hi - lo) * rng.uniform(0.0, 1.0, size=(n, len(self.features)))).astype(np.float32)
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

    @cached_property
    def question_index(self) -> dict[str, int]:
        """Question id -> its row in `weights` / `thresholds` (tree walks look it up per node)."""
        return {q: i for i, q in enumerate(self.questions)}

    def tree_action(self, tree: Tree, x: np.ndarray) -> int:
        """The action index a lexical tree picks for feature vector `x` (raw tests included);
        one walk down the tree, since rollouts and the exact model call it once a state."""
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        node = tree
        while isinstance(node, Node):
            w, c = self.question_test(node.question)
            node = node.yes if float(w @ x) > c else node.no
        return self.action_index(node.action)

    def tree_actions(self, tree: Tree, x: np.ndarray) -> np.ndarray:
        """The action index a lexical tree picks for each row of a batch of feature vectors; a
        learned test (``raw:<feature><op><value>``) answers on its feature."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))

        def act(node: Tree) -> np.ndarray:
            if isinstance(node, Leaf):
                return np.full(len(x), self.action_index(node.action), dtype=np.int64)
            w, c = self.question_test(node.question)
            return np.where(x @ w > c, act(node.yes), act(node.no))

        return act(tree)

    def question_test(self, question: str) -> tuple[np.ndarray, float]:
        """(weights over the features, threshold) of a question or a learned test: "yes" when
        weights . x > threshold (``raw:f<v`` is -x_f > -v), as ``answer_matrix`` answers."""
        i = self.question_index.get(question)
        if i is not None:
            return self.weights[i], float(self.thresholds[i])
        raw = parse_raw(question)
        if raw is None or raw.feature not in self.features:
            raise ValueError(f"{self.name} has no question {question!r}")
        sign = 1.0 if raw.greater else -1.0
        w = np.zeros(len(self.features))
        w[self.features.index(raw.feature)] = sign
        return w, sign * raw.value

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


ENV_PREFIX = "nl2policy/"


def read_spec(folder: Path) -> dict:
    """The folder's spec.toml as a dict; a ValueError naming the file if it cannot be read."""
    try:
        return tomllib.loads((folder / "spec.toml").read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{folder.name}/spec.toml: cannot be read ({exc})") from None


def env_ids(name: str, spec: Mapping[str, Any]) -> tuple[str, Optional[str]]:
    """(the env's id, the fast training env's id or None). An env whose code is in the folder
    (``[env] entry_point``) is registered as nl2policy/<name>-v0 and its training twin as
    nl2policy/<name>-train-v0, so a copied folder never collides with the original; an env
    registered elsewhere (Gymnasium's own) is named by ``[env] id``."""
    env, train = spec.get("env", {}), spec.get("train_env")
    if ("id" in env) == ("entry_point" in env):
        raise ValueError(f"{name}/spec.toml: [env] needs exactly one of id (a registered env) or entry_point (module:Class in the folder)")
    env_id = env["id"] if "id" in env else f"{ENV_PREFIX}{name}-v0"
    return env_id, (f"{ENV_PREFIX}{name}-train-v0" if train else None)


def load_domain(folder: Path, package: str, spec: Optional[dict] = None) -> Domain:
    """The domain whose spec.toml is in `folder` (`spec`: that file, where it was read already);
    `package` is the folder as a Python package."""
    name = folder.name
    where = f"{name}/spec.toml"
    spec = read_spec(folder) if spec is None else spec
    for table in ("questions", "actions", "tests"):
        if not spec.get(table):
            raise ValueError(f"{where}: no [{table}] table")
    features: Sequence[str] = spec["features"]
    vocab = Vocabulary(name, dict(spec["questions"]), dict(spec["actions"]), _units(spec, features, where))
    tests = spec["tests"]
    missing = set(vocab.questions) ^ set(tests)
    if missing:
        raise ValueError(f"{where}: questions and tests differ on {sorted(missing)}")
    weights = np.zeros((len(vocab.questions), len(features)))
    thresholds = np.zeros(len(vocab.questions))
    for i, q in enumerate(vocab.questions):
        for feat, w in tests[q]["weights"].items():
            if feat not in features:
                raise ValueError(f"{where}: question {q!r} weighs unknown feature {feat!r}")
            weights[i, features.index(feat)] = w
        thresholds[i] = tests[q]["threshold"]
    impossible = tuple(dict(rule) for rule in spec.get("impossible", []))
    one_hot = tuple(spec.get("one_hot", ()))
    if set(one_hot) - set(features):
        raise ValueError(f"{where}: one_hot names unknown features {sorted(set(one_hot) - set(features))}")
    ranges = spec.get("ranges", {})
    if ranges and set(ranges) != set(features):
        raise ValueError(f"{where}: [ranges] must give every feature a [low, high] and name no other")
    env_id, train_env_id = env_ids(name, spec)
    knobs = _knobs(spec, where)
    example_tree = None
    if "example_tree" in spec:
        try:
            example_tree = parse_tree(spec["example_tree"], vocab)
        except TreeError as exc:
            raise ValueError(f"{where}: example_tree: {exc}") from None
    return Domain(name, folder, package, vocab, tuple(features), weights, thresholds, impossible, env_id,
                  knobs, exact_model=spec.get("exact_model"), one_hot=one_hot,
                  train_env_id=train_env_id, title=spec.get("title", name.capitalize()),
                  example=spec.get("example", ""), example_tree=example_tree, briefing_section=spec.get("briefing_section"),
                  ceilings=spec.get("ceilings"), reference=spec.get("reference"),
                  translator=dict(spec.get("translator", {})),
                  ranges=tuple((float(ranges[f][0]), float(ranges[f][1])) for f in features) if ranges else ())


def _units(spec: dict, features: Sequence[str], where: str) -> dict[str, FeatureUnit]:
    """How each feature reads in a learned threshold test (trees/raw.py), from the optional
    [units] table: ``gap_ahead = { name = "the gap ...", scale = 100, unit = "m" }``; a feature
    it leaves out reads by its id, in feature units."""
    table = spec.get("units", {})
    unknown = set(table) - set(features)
    if unknown:
        raise ValueError(f"{where}: [units] names unknown features {sorted(unknown)}")
    out = {}
    for f in features:
        entry = table.get(f, {})
        if not isinstance(entry, dict) or set(entry) - {"name", "scale", "unit"}:
            raise ValueError(f"{where}: [units] {f}: give {{ name = ..., scale = ..., unit = ... }}")
        scale = entry.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not scale > 0:
            raise ValueError(f"{where}: [units] {f}: scale must be a number > 0, got {scale!r}")
        out[f] = FeatureUnit(str(entry.get("name", f)), float(scale), str(entry.get("unit", "")))
    return out


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
