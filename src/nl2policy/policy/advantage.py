"""The readable tree that PPO's own critic says does better than the policy it is training.

PPO's rollouts record, for each state visited, the action taken and its advantage (GAE: how much
better that action did than the critic expected of the policy there). A dictionary tree sees a
state only through its answers to the questions, so the states with the same answers form one
cell; the mean advantage of action a among the cell's samples estimates A(cell, a). The tree
maximizing sum over cells of visits(cell) * A(cell, tree(cell)) is one step of policy iteration
restricted to readable trees: to first order in the change of policy, the return it gains over
the current policy (Kakade & Langford, ICML 2002, the performance-difference lemma). Leaves get
the action the critic favours in their states and nodes the questions that separate states
where different actions pay, which gradient steps on a soft tree find slowly or not at all.

The step is only as good as the advantages. Each action's mean is taken relative to the cell's
mean advantage over all its samples (the policy's own actions average zero advantage, up to the
critic's error in that cell), and an action tried a few times has a noisy mean, so each (cell,
action) mean is shrunk toward the cell's by ``SHRINK`` pseudo-samples. An action never tried in a
cell scores zero there, as the cell's average does: below an action that did better than the
average and above one that did worse; among actions the critic cannot tell apart the policy's
likelier one wins. A leaf that serves several cells sums their scores, so it can pick an action
tried in none of them where every tried one did worse than average somewhere; such a tree is only
a candidate, scored like every reading before it is kept.

The rollouts are PPO's latest ``distill.VISITED`` states, which can span more than one chunk of
training: older ones carry the advantages of an earlier policy and critic. Whoever uses the tree
scores it first (``readings.checkpoint_tree_score`` keeps it only where it beats the other
readings).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from nl2policy.domains import get_domain
from nl2policy.policy.distill import fit_tree_scores
from nl2policy.trees import Tree

SHRINK = 10.0
"""Pseudo-samples at the cell's mean advantage added to every (cell, action): a mean from fewer
real samples than this counts for less than half of itself. A prior on noise, set before any run."""
TIE_BREAK = 1e-6
"""Weight of the policy's own probabilities: decides only between actions of equal advantage."""


def cell_scores(answers: np.ndarray, actions: np.ndarray, advantages: np.ndarray, probs: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(cells: distinct answer rows, scores: cells x actions) with score = visits(cell) x the
    action's mean advantage there relative to the cell's, shrunk, plus the tie-break."""
    cells, inverse = np.unique(np.asarray(answers, dtype=bool), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    n_actions = probs.shape[1]
    summed = np.zeros((len(cells), n_actions))
    counts = np.zeros((len(cells), n_actions))
    np.add.at(summed, (inverse, actions), advantages)
    np.add.at(counts, (inverse, actions), 1.0)
    visits = counts.sum(axis=1, keepdims=True)
    relative = summed - counts * summed.sum(axis=1, keepdims=True) / visits
    policy = np.zeros((len(cells), n_actions))
    np.add.at(policy, inverse, probs)
    return cells, visits * relative / (counts + SHRINK) + TIE_BREAK * policy


def advantage_tree(domain: str, probs: Callable[[np.ndarray], np.ndarray], states: np.ndarray,
                   actions: np.ndarray, advantages: np.ndarray) -> Tree:
    """The dictionary tree of at most 3 questions on a path that the critic's advantages on
    `states` (the actions taken there and their advantages) favour most (see the module doc)."""
    d = get_domain(domain)
    cells, scores = cell_scores(d.answer_matrix(states), actions, advantages, probs(states))
    return fit_tree_scores(cells, scores, list(d.questions), list(d.actions))
