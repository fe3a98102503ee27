"""Which tree tokens may come next: the grammar every decoder is held to.

Decoders emit a tree in pre-order (question ids open two slots, yes first; action ids close
one). Given the tokens so far, `next_slot` finds the open slot and what it may hold:
an action always; a question only above depth 3 and not already asked on the path; and
never the token that would make a "no" branch a copy of its "yes" sibling. Masking the
decoder's choices with this makes every finished output a valid tree of the domain.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

from nl2policy.trees import MAX_DEPTH, Vocabulary

BRANCH_ROOT, BRANCH_YES, BRANCH_NO = 0, 1, 2


@dataclass(frozen=True)
class Slot:
    """The next open slot: its depth, the questions above it, its parent's position in the
    token list (-1 for the root), which branch it is, its grid slot, and forbidden tokens."""

    depth: int
    path: tuple[str, ...]
    parent: int
    branch: int
    grid: int
    forbidden: frozenset[str]


def next_slot(prefix: Sequence[str], vocab: Vocabulary) -> Optional[Slot]:
    """The open slot after `prefix`, or None when `prefix` is a complete tree."""
    copies: list[tuple[int, Sequence[str]]] = []  # (start of a no-branch, its yes sibling's tokens)

    def walk(pos: int, depth: int, path: tuple[str, ...], parent: int, branch: int, grid: int):
        if pos == len(prefix):
            forbidden = {sib[-1] for start, sib in copies
                         if len(prefix) - start == len(sib) - 1 and list(prefix[start:]) == list(sib[:-1])}
            return Slot(depth, path, parent, branch, grid, frozenset(forbidden))
        tok = prefix[pos]
        if tok in vocab.actions:
            return pos + 1
        yes = walk(pos + 1, depth + 1, path + (tok,), pos, BRANCH_YES, 2 * grid + 1)
        if isinstance(yes, Slot):
            return yes
        copies.append((yes, prefix[pos + 1:yes]))
        no = walk(yes, depth + 1, path + (tok,), pos, BRANCH_NO, 2 * grid + 2)
        copies.pop()
        return no

    result = walk(0, 0, (), -1, BRANCH_ROOT, 0)
    return result if isinstance(result, Slot) else None


def allowed_tokens(slot: Slot, vocab: Vocabulary) -> list[str]:
    """Tokens the open slot may hold, in vocabulary order (questions, then actions)."""
    questions = [] if slot.depth >= MAX_DEPTH else [q for q in vocab.question_ids if q not in slot.path]
    return [t for t in questions + vocab.action_ids if t not in slot.forbidden]
