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
    `labels` (action indices) over boolean `answers` (states x questions), exactly. A split must
    send states both ways and lower the cost, so no node asks in vain; ties keep the smaller tree."""
    answers = np.asarray(answers, dtype=bool)
    labels = np.asarray(labels, dtype=np.int64)
    weights = np.asarray(weights, dtype=np.float64)
    n_actions = len(actions)
    eps = 1e-9 * max(float(weights.sum()), 1.0)

    def best(mask: np.ndarray, used: frozenset, left: int) -> tuple[float, Tree]:
        tally = np.bincount(labels[mask], weights[mask], minlength=n_actions)
        top = int(np.argmax(tally))
        cost, tree = float(tally.sum() - tally[top]), Leaf(actions[top])
        if left == 0 or cost <= eps:
            return cost, tree
        for q in range(len(questions)):
            if q in used:
                continue
            yes = mask & answers[:, q]
            no = mask & ~answers[:, q]
            if not yes.any() or not no.any():
                continue
            c_yes, t_yes = best(yes, used | {q}, left - 1)
            c_no, t_no = best(no, used | {q}, left - 1)
            if c_yes + c_no < cost - eps:
                cost, tree = c_yes + c_no, Node(questions[q], t_yes, t_no)
        return cost, tree

    return best(np.ones(len(labels), dtype=bool), frozenset(), depth)[1]


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
    """Keeps the feature rows of PPO's latest rollouts (at most VISITED): the states the policy
    being trained goes to, which its distilled tree is fitted on."""

    def __init__(self, keep: int = VISITED) -> None:
        super().__init__()
        self.rows: deque = deque(maxlen=keep)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        obs = np.asarray(self.model.rollout_buffer.observations)
        self.rows.extend(obs.reshape(-1, obs.shape[-1]))

    def states(self) -> Optional[np.ndarray]:
        return np.array(self.rows) if self.rows else None
