"""The readable tree that acts most like a trained policy where that policy goes.

Rounding a soft DDT to its nearest crisp tree (``convert.ddt_to_tree``) keeps each node's
strongest feature and each leaf's likeliest action; where PPO has learned soft, overlapping
splits, that tree can act far from the policy it came from (Table 2: lunar's soft DDT beat its
rounded tree by 123 points). Distillation asks instead: among the trees of the domain's
dictionary with at most 3 questions on a path, which one takes the policy's action in the states
the policy visits, most of all where a wrong action costs most? That is VIPER's fit (Bastani et
al., NeurIPS 2018), done exactly: the best subtree for the states reaching a node depends only on
those states and the questions left, so a dynamic programme over paths finds the optimal tree.

What a wrong action costs in a state is read from the policy itself: an entropy-regularized
policy is close to softmax(Q / alpha), so log pi(best) - log pi(worst) measures (Q_max - Q_min) /
alpha, VIPER's weight up to a constant (PPO keeps no Q of its own).
"""

from __future__ import annotations

from collections import deque
from typing import Callable, Optional

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from nl2policy.domains import get_domain
from nl2policy.trees import Leaf, Node, Tree

MIN_PROB = 1e-6
"""Floor on action probabilities before their logs are taken (a gap of at most log(1e6) = 13.8)."""
VISITED = 20_000
"""States of the latest rollouts a distillation fits: recent enough to be the policy's own."""


def fit_tree(answers: np.ndarray, labels: np.ndarray, weights: np.ndarray, questions: list[str],
             actions: list[str], depth: int = 3) -> Tree:
    """The tree of at most `depth` questions on a path with the least weighted disagreement with
    `labels` (action indices) over boolean `answers` (states x questions), exactly: the tree
    ``fit_tree_scores`` finds when a state scores its weight for its label's action."""
    labels = np.asarray(labels, dtype=np.int64)
    scores = np.zeros((len(labels), len(actions)))
    scores[np.arange(len(labels)), labels] = np.asarray(weights, dtype=np.float64)
    return fit_tree_scores(answers, scores, questions, actions, depth)


def fit_tree_scores(answers: np.ndarray, scores: np.ndarray, questions: list[str], actions: list[str],
                    depth: int = 3) -> Tree:
    """The tree of at most `depth` questions on a path that maximizes the summed score of the
    action it takes in each state (`scores`: states x actions) over boolean `answers` (states x
    questions), exactly. A tree sees a state only through its answers, so states with the same
    answers are summed first. A split must send states both ways and raise the total, so no node
    asks in vain; of trees scoring the same (within rounding) the one with fewer questions wins, and
    in a leaf the first action."""
    answers = np.asarray(answers, dtype=bool)
    cells, inverse = np.unique(answers, axis=0, return_inverse=True)
    totals = np.zeros((len(cells), len(actions)))
    np.add.at(totals, inverse.reshape(-1), np.asarray(scores, dtype=np.float64))
    eps = 1e-9 * max(float(np.abs(totals).sum()), 1.0)

    def best(mask: np.ndarray, used: frozenset, left: int) -> tuple[float, int, Tree]:
        """(value, questions asked, tree) of the best subtree for the cells in `mask`."""
        tally = totals[mask].sum(axis=0)
        top = int(np.argmax(tally))
        value, size, tree = float(tally[top]), 0, Leaf(actions[top])
        if left == 0:
            return value, size, tree
        for q in range(len(questions)):
            if q in used:
                continue
            yes = mask & cells[:, q]
            no = mask & ~cells[:, q]
            if not yes.any() or not no.any():
                continue
            v_yes, s_yes, t_yes = best(yes, used | {q}, left - 1)
            v_no, s_no, t_no = best(no, used | {q}, left - 1)
            v, s = v_yes + v_no, s_yes + s_no + 1
            if v > value + eps or (v >= value - eps and s < size):
                value, size, tree = v, s, Node(questions[q], t_yes, t_no)
        return value, size, tree

    return best(np.ones(len(cells), dtype=bool), frozenset(), depth)[2]


def labels_and_weights(probs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A policy's greedy action in each state and what a wrong action costs there."""
    logp = np.log(np.clip(probs, MIN_PROB, 1.0))
    return probs.argmax(axis=1), logp.max(axis=1) - logp.min(axis=1)


def distilled_tree(domain: str, probs: Callable[[np.ndarray], np.ndarray], states: np.ndarray) -> Tree:
    """The dictionary tree that best imitates the policy `probs` (feature rows -> action
    probabilities) on `states` (feature rows)."""
    d = get_domain(domain)
    labels, weights = labels_and_weights(probs(states))
    return fit_tree(d.answer_matrix(states), labels, weights, list(d.questions), list(d.actions))


class VisitedStates(BaseCallback):
    """Keeps the feature rows of PPO's latest rollouts (at most VISITED), with the action taken in
    each and its advantage (SB3's GAE, computed before the rollout ends): the states the policy
    being trained goes to, which its distilled tree is fitted on, and what its critic said of
    each action there (``advantage.advantage_tree``)."""

    def __init__(self, keep: int = VISITED) -> None:
        super().__init__()
        self.rows: deque = deque(maxlen=keep)
        self.actions: deque = deque(maxlen=keep)
        self.advantages: deque = deque(maxlen=keep)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        buffer = self.model.rollout_buffer
        obs = np.asarray(buffer.observations)
        self.rows.extend(obs.reshape(-1, obs.shape[-1]))
        self.actions.extend(np.asarray(buffer.actions).reshape(-1).astype(np.int64))
        self.advantages.extend(np.asarray(buffer.advantages).reshape(-1))

    def states(self) -> Optional[np.ndarray]:
        return np.array(self.rows) if self.rows else None

    def taken(self) -> tuple[np.ndarray, np.ndarray]:
        """(action index, advantage) for each row of ``states()``."""
        return np.array(self.actions, dtype=np.int64), np.array(self.advantages, dtype=np.float64)
