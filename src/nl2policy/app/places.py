"""Places in a tree in words: "slot 6" (the grid) and "root.yes.no" (tree JSON) are how the
code finds a node; a person reads 'the "no" answer to "Is the road to the city jammed?"'."""

from __future__ import annotations

from typing import Any, Optional

from nl2policy.trees import Vocabulary


def _words(vocab: Vocabulary, item: Optional[str]) -> str:
    return vocab.wording(item) if item else "an empty box"


def slot_place(slot: int, grid: list, vocab: Vocabulary) -> str:
    """Slot 0 is the first question; slot s hangs on the yes (odd s) or no (even s) side of (s-1)//2."""
    if slot == 0:
        return "the first question"
    parent, answer = (slot - 1) // 2, "yes" if slot % 2 else "no"
    asked = grid[parent] if 0 <= parent < len(grid) else None
    return f'the "{answer}" answer to "{_words(vocab, asked)}"'


def path_place(where: str, tree: Any, vocab: Vocabulary) -> str:
    """'root.yes.no' in a tree JSON object -> the same words as `slot_place`."""
    parts = where.split(".")
    if parts[0] != "root" or any(p not in ("yes", "no") for p in parts[1:]):
        return where
    if len(parts) == 1:
        return "the first question"
    node = tree
    for answer in parts[1:-1]:
        node = node.get(answer) if isinstance(node, dict) else None
    asked = node.get("if") if isinstance(node, dict) else None
    return f'the "{parts[-1]}" answer to "{_words(vocab, asked)}"'


def place(where: str, vocab: Vocabulary, tree: Any = None, grid: Optional[list] = None) -> str:
    """Words for a TreeError's `where`, given what was parsed."""
    if where.startswith("slot ") and where[5:].isdigit() and grid is not None:
        return slot_place(int(where[5:]), grid, vocab)
    if where.startswith("root"):
        return path_place(where, tree, vocab)
    return where
