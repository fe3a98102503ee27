"""Counterfactual copies of real descriptions: the actions a description names, permuted in its
text and its tree alike.

Why: the corpus teaches strong habits. In taxi, a "not in the village" branch that ends in an
action drives to the village 36 times out of 39, so a translator learns to write go_village
there whatever the text says, and the rare description that says "not in the village: go to
the city" is translated wrong. A copy of a real description in which "drive to the city" became
"drive to the airport", with the tree's go_city leaves turned into go_airport, is still in the
writer's own style, but the action can only be got by reading it.

Only action mentions the patterns of mentions.py recognise are rewritten (a verb phrase and its
destination, an arrow and its action), and a description is used only when the actions it is
seen to mention are exactly the tree's actions of each permuted group, so that no mention is
left pointing at the old action. A permutation keeps a tree valid: two sibling leaves that
differed still differ.
"""

from __future__ import annotations

import random
from itertools import permutations
from typing import Optional

from nl2policy.language.mentions import GROUPS, find_mentions
from nl2policy.trees import Leaf, Node, Tree
from nl2policy.trees.tree import iter_leaves


def _relabel(tree: Tree, mapping: dict[str, str]) -> Tree:
    if isinstance(tree, Leaf):
        return Leaf(mapping.get(tree.action, tree.action))
    return Node(tree.question, _relabel(tree.yes, mapping), _relabel(tree.no, mapping))


def _match_case(new: str, old: str) -> str:
    return new.capitalize() if old[:1].isupper() else new


def swap_actions(domain: str, text: str, tree: Tree, rng: random.Random) -> Optional[tuple[str, Tree]]:
    """A copy of (text, tree) with the actions of each domain group permuted at random in both,
    or None when the text's mentions do not account for the tree's actions (or nothing would change)."""
    edits: list[tuple[int, int, str]] = []
    mapping: dict[str, str] = {}
    tree_actions = {leaf.action for leaf in iter_leaves(tree)}
    for group in GROUPS.get(domain, []):
        found = find_mentions(group, text)
        named = {action for *_, action in found}
        if named != tree_actions & set(group.actions):
            return None
        if not named:
            continue
        order = [p for p in permutations(group.actions) if p != group.actions]
        perm = dict(zip(group.actions, rng.choice(order)))
        mapping.update(perm)
        edits += [(s, e, _match_case(group.rewrite(form, perm[action]), form)) for s, e, form, action in found]
    if not edits or all(mapping.get(a, a) == a for a in tree_actions):
        return None
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text, _relabel(tree, mapping)
