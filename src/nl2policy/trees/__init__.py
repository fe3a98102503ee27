"""Lexical decision trees: the readable policy a person writes, edits and gets back.

A tree is a `Leaf` (an action id) or a `Node` (a question id with a yes and a no branch),
at most `MAX_DEPTH` questions on any root-to-leaf path. Ids come from a `Vocabulary`, so this
package knows nothing of taxis or highways.
"""

from nl2policy.trees.tree import Leaf, Node, Tree, MAX_DEPTH, GRID_SLOTS, Vocabulary
from nl2policy.trees.errors import TreeError
from nl2policy.trees.parse import parse_tree, tree_to_json, load_tree_arg
from nl2policy.trees.tokens import to_tokens, from_tokens
from nl2policy.trees.grid import to_grid, from_grid
from nl2policy.trees.render import to_text, to_dot, to_svg
from nl2policy.trees.raw import RAW_PREFIX, FeatureUnit, RawTest, parse_raw

__all__ = [
    "Leaf", "Node", "Tree", "MAX_DEPTH", "GRID_SLOTS", "Vocabulary", "TreeError",
    "parse_tree", "tree_to_json", "load_tree_arg", "to_tokens", "from_tokens",
    "to_grid", "from_grid", "to_text", "to_dot", "to_svg", "RAW_PREFIX", "FeatureUnit", "RawTest", "parse_raw",
]
