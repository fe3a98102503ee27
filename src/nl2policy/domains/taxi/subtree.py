"""Taxi's larger polish moves (policy/polish.py asks the exact model for them through
``TaxiExact.subtree_search``): a whole subtree re-solved exactly over every map of its states
to actions that a subtree can induce, and both branches of the root re-solved together by the
ceilings' branch and bound."""

from __future__ import annotations

from typing import Optional

import numpy as np

from nl2policy.domains import get_domain
from nl2policy.policy.polish import MIN_GAIN, _normalize, _positions, _replace
from nl2policy.trees import MAX_DEPTH, Node, Tree, TreeError
from nl2policy.trees.parse import validate

from .ceilings import TreeMaps, _returns, best_tree
from .tables import effective_action


class SubtreeSearch:
    """The best replacement of one proper subtree, exactly: every map from the states that reach
    the subtree's position to actions that a subtree of the allowed depth induces (one tree per
    map, ceilings.TreeMaps), each joined with the rest of the tree's policy and scored in
    one batch on the exact model's tables."""

    def __init__(self, domain: str) -> None:
        self.domain = get_domain(domain)
        self.tables = self.domain.exact.tables()
        self.maps = TreeMaps(self.tables, domain)
        self.reach = tuple(self.tables.reachable())
        self.below_root: dict[str, float] = {}  # root question -> the best return under it, once searched

    def _policy(self, tree: Tree):
        """The tree's effective action in every reachable state (as TreeMaps.policies lays them out)."""
        index = self.domain.action_index
        row = [effective_action(self.tables.states[s], index(tree.act(self.maps.answers[s]))) for s in self.reach]
        return self.maps.policies(self.reach, [tuple(row)])[0]

    def best_replacement(self, tree: Tree, value: float) -> tuple[Optional[Tree], int]:
        """(the best tree one subtree replacement away if it beats `value`, else None; maps scored)."""
        base, best, best_value, scored = self._policy(tree), None, value + MIN_GAIN, 0
        for path, _ in list(_positions(tree))[1:]:
            states = tuple(s for s in self.reach if all(self.maps.answers[s][q] == a for q, a in path))
            if not states:
                continue
            options = self.maps.realizable(states, MAX_DEPTH - len(path))
            keys = list(options)
            policies = np.repeat(base[None], len(keys), 0)
            policies[:, list(states)] = np.array(keys)
            values = _returns(self.tables, policies)
            scored += len(keys)
            for k in np.argsort(-values):
                if values[k] <= best_value:
                    break
                try:
                    candidate = validate(_normalize(_replace(tree, path, options[keys[k]])), self.domain.vocab)
                except TreeError:
                    continue
                best, best_value = candidate, float(values[k])
                break
        return best, scored

    def best_below_root(self, tree: Tree, value: float) -> tuple[Optional[Tree], int]:
        """(the best tree with `tree`'s root question, both branches re-solved together, if it
        beats `value`, else None; candidate pairs scored)."""
        if not isinstance(tree, Node):
            return None, 0
        if self.below_root.get(tree.question, float("inf")) <= value + MIN_GAIN:
            return None, 0  # searched under this root already, and `tree` is as good as its best
        found = best_tree(self.tables, MAX_DEPTH, roots=[tree.question])
        self.below_root[tree.question] = found.value if getattr(found.tree, "question", None) == tree.question else value
        scored = found.counts["pairs_scored"]
        if getattr(found.tree, "question", None) != tree.question or found.value <= value + MIN_GAIN:
            return None, scored  # (a shallower incumbent with another root is not this move)
        try:
            return validate(_normalize(found.tree), self.domain.vocab), scored
        except TreeError:
            return None, scored
