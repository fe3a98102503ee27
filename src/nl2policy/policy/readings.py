"""How the tree a training DDT hands back is read at each checkpoint, and how PPO is moved
onto it.

A soft DDT is not a tree; ``optimize.train_checkpointed`` asks ``checkpoint_tree_score`` for
the tree at each checkpoint (the best of several readings, scored as keep-best scores trees), and
where the domain's ``adopt_read_tree`` knob is on it moves the DDT onto that tree with
``tree_adopter``.
"""

from __future__ import annotations

from typing import Callable, Optional

from stable_baselines3 import PPO

from nl2policy.domains import get_domain
from nl2policy.domains.spec import Knobs
from nl2policy.policy.advantage import advantage_tree
from nl2policy.policy.convert import ddt_to_tree, load_tree
from nl2policy.policy.distill import VisitedStates, distilled_tree
from nl2policy.policy.keep_best import tree_scorer
from nl2policy.policy.sb3_policy import action_probs_fn, actor_ddt
from nl2policy.trees import Tree, tree_to_json


TreeScore = Callable[[PPO, Optional[VisitedStates]], tuple[dict, float, str]]
"""(model, its latest rollouts or None) -> (the tree it hands back as JSON, that tree's score, how
the tree was read from the model: "rounded", "distilled" or "critic")."""


def checkpoint_tree_score(domain: str, sampled: bool = False,
                          scorer: Optional[Callable[[Tree], float]] = None,
                          critic: Optional[bool] = None) -> Optional[TreeScore]:
    """How to read and score the tree of the policy at each checkpoint (``keep_best.tree_scorer``),
    or None.

    Readings of the trained DDT compete: its rounding (``ddt_to_tree``: each node's strongest
    feature, each leaf's likeliest action), and, given PPO's latest rollouts, its distillation
    (``distill.distilled_tree``: the dictionary tree acting most like it in the states visited)
    and, with `critic` (default: the domain's ``critic_reading`` knob), the tree its critic's
    advantages favour there (``advantage.advantage_tree``). The best by `scorer` is the
    checkpoint's tree (a tie keeps the earlier reading, in that order).

    With an exact model (taxi): the exact expected return (~0.1 s, no sampling noise). PPO's tree
    wanders between checkpoints (measured: results/policy/tuning_taxi.md), so the run also keeps
    the best tree it passed through, the way one keeps the best checkpoint on a validation score.
    Without one (highway), sampled episodes cost seconds each: only where `sampled` asks for it
    (``optimize`` does, to return a tree never worse than its start; the Table 2 grid does too).
    `scorer`: one already made, to share its cache of sampled scores."""
    d = get_domain(domain)
    if d.exact is None and not sampled:
        return None
    scorer = scorer or tree_scorer(domain)[0]
    critic = d.knobs.critic_reading if critic is None else critic

    def score(model: PPO, rollouts: Optional[VisitedStates] = None) -> tuple[dict, float, str]:
        tree, read = ddt_to_tree(domain, actor_ddt(model)), "rounded"
        value = scorer(tree)
        states = rollouts.states() if rollouts is not None else None
        if states is not None and len(states):
            probs = action_probs_fn(model)
            readings = [("distilled", lambda: distilled_tree(domain, probs, states))]
            if critic:
                readings.append(("critic", lambda: advantage_tree(domain, probs, states, *rollouts.taken())))
            for name, reading in readings:
                other = reading()
                other_value = scorer(other)
                if other_value > value:
                    tree, value, read = other, other_value, name
        return tree_to_json(tree), value, read

    return score


def tree_adopter(domain: str, knobs: Optional[Knobs] = None) -> Callable[[PPO, Tree], None]:
    """Moves a training tree-DDT onto a tree read from it (``optimize.train_checkpointed``'s
    `adopt`): its tests and leaves are set as a fresh tree-initialized DDT's (``convert.load_tree``,
    the leaf mass from `knobs`), and Adam's running moments for them are dropped, so that the next
    update starts from the tree rather than from the old parameters' momentum.

    Why: the critic's and the distilled readings find trees better than the DDT's own, and PPO
    then trains the tree it will hand back, a step of policy iteration between chunks of policy
    gradient. Measured on highway's Table 2 (results/policy/ablation_critic_adopt*/): the soft
    policy ends within 0.5 of its tree in more runs than with the readings alone, but the kept
    tree is lower, so no domain turns it on (the knob ``adopt_read_tree``)."""
    leaf_mass = (knobs or get_domain(domain).knobs).leaf_mass

    def adopt(model: PPO, tree: Tree) -> None:
        ddt = actor_ddt(model)
        load_tree(ddt, domain, tree, leaf_mass)
        for parameter in ddt.parameters():
            model.policy.optimizer.state.pop(parameter, None)

    return adopt
