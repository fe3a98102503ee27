"""The tree data type and what a tree can do on its own: act, measure itself, list questions."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator, Mapping, Union

from nl2policy.trees.raw import FeatureUnit, parse_raw

MAX_DEPTH = 3
"""Most questions on any root-to-leaf path: the paper's 4-level grid."""

GRID_SLOTS = 2 ** (MAX_DEPTH + 1) - 1
"""15 slots: a complete binary tree of 4 levels."""


@dataclass(frozen=True)
class Vocabulary:
    """The ids a domain allows, with their wording, in a fixed order.

    Order matters: it fixes token ids for the translators and action indices for the envs.
    """

    domain: str
    questions: Mapping[str, str]
    actions: Mapping[str, str]
    # The policy's input features and how each reads: a learned test on one of them
    # (``raw:<feature><op><value>``, trees/raw.py) is a question too. Empty: no raw tests.
    features: Mapping[str, FeatureUnit] = field(default_factory=dict)

    def __post_init__(self) -> None:
        clash = set(self.questions) & set(self.actions)
        if clash:
            raise ValueError(f"ids used as both question and action: {sorted(clash)}")

    def dictionary_only(self) -> "Vocabulary":
        """The same ids without learned tests: what a person writes and the corpus holds."""
        return Vocabulary(self.domain, self.questions, self.actions)

    def is_question(self, item: str) -> bool:
        """A dictionary question, or a raw threshold test on one of the features."""
        if item in self.questions:
            return True
        raw = parse_raw(item)
        return raw is not None and raw.feature in self.features

    def wording(self, item: str) -> str:
        """How a person reads an id: its dictionary wording, a raw test in the feature's units,
        or the id itself where it is neither."""
        if item in self.questions:
            return self.questions[item]
        if item in self.actions:
            return self.actions[item]
        raw = parse_raw(item)
        if raw is not None and raw.feature in self.features:
            return raw.wording(self.features[raw.feature])
        return item

    @property
    def question_ids(self) -> list[str]:
        return list(self.questions)

    @property
    def action_ids(self) -> list[str]:
        return list(self.actions)


@dataclass(frozen=True)
class Leaf:
    action: str

    def act(self, answers: Mapping[str, bool]) -> str:
        return self.action


@dataclass(frozen=True)
class Node:
    question: str
    yes: "Tree"
    no: "Tree"

    def act(self, answers: Mapping[str, bool]) -> str:
        """Follow the answers down to an action; `answers` maps question id to True/False."""
        node: Tree = self
        while isinstance(node, Node):
            node = node.yes if answers[node.question] else node.no
        return node.action


Tree = Union[Leaf, Node]


def depth(tree: Tree) -> int:
    """Number of questions on the longest root-to-leaf path."""
    if isinstance(tree, Leaf):
        return 0
    return 1 + max(depth(tree.yes), depth(tree.no))


def questions_used(tree: Tree) -> set[str]:
    return {n.question for n in iter_nodes(tree)}


def iter_nodes(tree: Tree) -> Iterator[Node]:
    """Internal nodes in pre-order."""
    if isinstance(tree, Node):
        yield tree
        yield from iter_nodes(tree.yes)
        yield from iter_nodes(tree.no)


def iter_leaves(tree: Tree) -> Iterator[Leaf]:
    if isinstance(tree, Leaf):
        yield tree
    else:
        yield from iter_leaves(tree.yes)
        yield from iter_leaves(tree.no)


def size(tree: Tree) -> int:
    """Number of nodes and leaves."""
    return 1 if isinstance(tree, Leaf) else 1 + size(tree.yes) + size(tree.no)
