"""The paper's 15-slot grid: slot i has its yes child at 2i+1 and its no child at 2i+2.

Slots below a leaf are empty (None). This is the layout the data-collection page shows and
the layout the DDT pads to.
"""

from __future__ import annotations

from typing import Optional, Sequence

from nl2policy.trees.errors import TreeError
from nl2policy.trees.parse import unknown_question, validate
from nl2policy.trees.raw import RAW_PREFIX
from nl2policy.trees.tree import GRID_SLOTS, Leaf, Node, Tree, Vocabulary

Grid = list[Optional[str]]


def to_grid(tree: Tree) -> Grid:
    grid: Grid = [None] * GRID_SLOTS

    def place(node: Tree, slot: int) -> None:
        if slot >= GRID_SLOTS:
            raise TreeError("tree is deeper than the 15-slot grid", f"slot {slot}")
        if isinstance(node, Leaf):
            grid[slot] = node.action
        else:
            grid[slot] = node.question
            place(node.yes, 2 * slot + 1)
            place(node.no, 2 * slot + 2)

    place(tree, 0)
    return grid


def from_grid(grid: Sequence[Optional[str]], vocab: Vocabulary) -> Tree:
    if len(grid) != GRID_SLOTS:
        raise TreeError(f"a grid has {GRID_SLOTS} slots, got {len(grid)}", "grid")
    used: set[int] = set()

    def build(slot: int) -> Tree:
        if slot >= GRID_SLOTS:
            raise TreeError("a question in the bottom row has no slots for its answers", f"slot {(slot - 1) // 2}")
        item = grid[slot]
        used.add(slot)
        if item is None:
            raise TreeError("empty slot where a question's branch must go", f"slot {slot}")
        if item in vocab.actions:
            return Leaf(item)
        if vocab.is_question(item):
            return Node(item, build(2 * slot + 1), build(2 * slot + 2))
        if isinstance(item, str) and item.startswith(RAW_PREFIX):
            raise TreeError(unknown_question(item, vocab), f"slot {slot}")
        raise TreeError(f"unknown id {item!r}", f"slot {slot}")

    tree = build(0)
    stray = [i for i, item in enumerate(grid) if item is not None and i not in used]
    if stray:
        raise TreeError("filled slot hangs below an action or an empty slot", f"slot {stray[0]}")
    return validate(tree, vocab)
