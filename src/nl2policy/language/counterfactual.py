"""Counterfactual copies of real descriptions: the actions a description names, permuted in its
text and its tree alike.

Why: the corpus teaches strong habits. In taxi, a "not in the village" branch that ends in an
action drives to the village 36 times out of 39, so a translator learns to write go_village
there whatever the text says, and the rare description that says "not in the village: go to
the city" is translated wrong. A copy of a real description in which "drive to the city" became
"drive to the airport", with the tree's go_city leaves turned into go_airport, is still in the
writer's own style, but the action can only be got by reading it.

Only action mentions the patterns below recognise are rewritten (a verb phrase and its
destination, an arrow and its action), and a description is used only when the actions it is
seen to mention are exactly the tree's actions of each permuted group, so that no mention is
left pointing at the old action. A permutation keeps a tree valid: two sibling leaves that
differed still differ.
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass
from itertools import permutations
from typing import Optional

from nl2policy.trees import Leaf, Node, Tree
from nl2policy.trees.tree import iter_leaves


@dataclass(frozen=True)
class ActionGroup:
    """Actions that may be permuted among themselves. `pattern` finds a mention; its group
    `key` is the part naming the action, `lookup` maps that part (lowercased) to the action,
    and `wording[action]` maps the mentioned form to how the other actions say it."""

    actions: tuple[str, ...]
    pattern: re.Pattern
    lookup: dict[str, str]
    wording: dict[str, dict[str, str]]  # action -> {mentioned form: replacement}, "*" for any form

    def rewrite(self, form: str, action: str) -> str:
        table = self.wording[action]
        return table.get(form.lower(), table.get("*", form))


_VERB = (r"(?:drive|drives|driving|go|goes|going|head|heads|heading|leave|leaves|return|returns|take|takes|"
         r"bring|move|moves|get|gets|back|straight|right|off|over|on|them|him|her|it|out|away|directly|"
         r"immediately|just|then|always)")
_TAXI = re.compile(
    rf"\b{_VERB}\s+(?:{_VERB}\s+){{0,3}}(?:to|for|towards|toward|into)\s+(?:the\s+)?(?P<key>airport|village|city)\b"
    rf"|(?:->|→|=>|:)\s*(?:go\s+|drive\s+|head\s+)?(?:to\s+)?(?:the\s+)?(?P<key2>airport|village|city)\b", re.I)

_SPEED_FORMS = {  # each form of "speed up" and its "slow down" counterpart, both ways
    "speed up": "slow down", "speeds up": "slows down", "speeding up": "slowing down",
    "accelerate": "brake", "accelerates": "brakes", "accelerating": "braking", "go faster": "go slower",
}
_SPEED_BACK = {v: k for k, v in _SPEED_FORMS.items()}
_SPEED_BACK.update({"decelerate": "accelerate", "decelerates": "accelerates"})
_SPEED = re.compile(r"\b(?P<key>" + "|".join(sorted(map(re.escape, list(_SPEED_FORMS) + list(_SPEED_BACK)),
                                                   key=len, reverse=True)) + r")\b", re.I)
_LANE = re.compile(r"\b(?:move|moves|moving|change|changes|changing|switch|switches|merge|merges|go|goes|shift|shifts|"
                   r"pull|pulls|get|gets|steer|steers)\s+(?:over\s+|one\s+lane\s+|back\s+)?(?:(?:in)?to\s+)?(?:the\s+)?"
                   r"(?P<key>left|right)\b", re.I)

GROUPS: dict[str, list[ActionGroup]] = {
    "taxi": [ActionGroup(("go_airport", "go_village", "go_city"), _TAXI,
                         {"airport": "go_airport", "village": "go_village", "city": "go_city"},
                         {"go_airport": {"*": "airport"}, "go_village": {"*": "village"}, "go_city": {"*": "city"}})],
    "highway": [
        ActionGroup(("lane_left", "lane_right"), _LANE, {"left": "lane_left", "right": "lane_right"},
                    {"lane_left": {"*": "left"}, "lane_right": {"*": "right"}}),
        ActionGroup(("faster", "slower"), _SPEED,
                    {**{f: "faster" for f in _SPEED_FORMS}, **{f: "slower" for f in _SPEED_BACK}},
                    {"slower": dict(_SPEED_FORMS), "faster": dict(_SPEED_BACK)}),
    ],
}


def _mentions(group: ActionGroup, text: str) -> list[tuple[int, int, str, str]]:
    """(start, end, mentioned form, action) of each action mention the group's pattern finds."""
    out = []
    for m in group.pattern.finditer(text):
        key = "key" if m.group("key") is not None else "key2"
        form = m.group(key)
        out.append((m.start(key), m.end(key), form, group.lookup[form.lower()]))
    return out


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
        found = _mentions(group, text)
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
