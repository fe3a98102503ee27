"""Pre-order token sequences: what the sequence decoders emit.

Question and action ids are disjoint, so a pre-order listing is enough to rebuild the tree:
a question token opens two subtrees (yes first), an action token closes one.
"""

from __future__ import annotations

from typing import Sequence

from nl2policy.trees.errors import TreeError
from nl2policy.trees.parse import validate
from nl2policy.trees.tree import Leaf, Node, Tree, Vocabulary


def to_tokens(tree: Tree) -> list[str]:
    if isinstance(tree, Leaf):
        return [tree.action]
    return [tree.question, *to_tokens(tree.yes), *to_tokens(tree.no)]


def from_tokens(tokens: Sequence[str], vocab: Vocabulary) -> Tree:
    pos = 0

    def build() -> Tree:
        nonlocal pos
        if pos >= len(tokens):
            raise TreeError("sequence ends before every question has both branches", f"token {pos}")
        tok = tokens[pos]
        pos += 1
        if tok in vocab.actions:
            return Leaf(tok)
        if tok in vocab.questions:
            yes = build()
            no = build()
            return Node(tok, yes, no)
        raise TreeError(f"unknown token {tok!r}", f"token {pos - 1}")

    tree = build()
    if pos != len(tokens):
        raise TreeError(f"{len(tokens) - pos} tokens left after a complete tree", f"token {pos}")
    return validate(tree, vocab)
