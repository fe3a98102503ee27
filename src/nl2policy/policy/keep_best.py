"""Verified keep-best: ``optimize`` returns the best of the tree it was given and every
checkpoint's discretized tree, so it never hands back a worse tree than it got.

"Best" is judged where the domain allows it without noise: on the exact model (taxi), or else
on sampled episodes from ``SELECT_SEED``: the knobs' ``select_episodes`` episodes of the
domain's fast vector env where it has one (highway: 500 twin episodes), else its
``eval_episodes`` episodes of the reference env. Common random numbers: every tree meets the
same traffic, so a tree replaces the incumbent only by driving better on those episodes. The seeds differ from ``EVAL_SEED``, on which ``optimize`` reports
returns, so a reported improvement is not the selection's own noise.
"""

from __future__ import annotations

import json
from typing import Callable

from nl2policy.domains import get_domain
from nl2policy.policy.convert import tree_act_fn, tree_batch_act_fn
from nl2policy.policy.rollout import evaluate, evaluate_batched
from nl2policy.trees import Leaf, Node, Tree, tree_to_json

SELECT_SEED = 60_000  # keep-best's sampled episodes: apart from EVAL_SEED (50,000 on) and training's


def tree_scorer(domain: str) -> tuple[Callable[[Tree], float], str]:
    """How keep-best scores a tree, and that rule in words. Sampled scores are cached by tree
    (PPO's discretized tree often repeats between checkpoints)."""
    d = get_domain(domain)
    if d.exact is not None:
        return (lambda tree: float(d.exact.expected_return(tree_act_fn(domain, tree)))), "exact expected return"
    cache: dict[str, float] = {}
    if d.train_env_id is not None and d.knobs.select_episodes:
        n = d.knobs.select_episodes

        def score(tree: Tree) -> float:
            return evaluate_batched(domain, tree_batch_act_fn(domain, tree), n, SELECT_SEED).mean_return

        rule = f"mean return over {n} episodes of {d.train_env_id}, seed {SELECT_SEED}"
    else:
        n = d.knobs.eval_episodes

        def score(tree: Tree) -> float:
            return evaluate(domain, tree_act_fn(domain, tree), n, SELECT_SEED).mean_return

        rule = f"mean return over {n} episodes, seeds {SELECT_SEED}-{SELECT_SEED + n - 1}"

    def sampled(tree: Tree) -> float:
        key = json.dumps(tree_to_json(tree), sort_keys=True)
        if key not in cache:
            cache[key] = score(tree)
        return cache[key]

    return sampled, rule


def tree_from_json(data: dict) -> Tree:
    """A tree from its JSON without the vocabulary's checks: a discretized tree may hold raw
    threshold tests (``convert.RAW_PREFIX``) that no question names."""
    if "do" in data:
        return Leaf(data["do"])
    return Node(data["if"], tree_from_json(data["yes"]), tree_from_json(data["no"]))


def keep_best(initial: Tree, initial_score: float, best_checkpoint: dict) -> tuple[Tree, float, str]:
    """The initial tree unless the best checkpoint tree (``{"tree", "score", "step"}``) scored
    strictly higher: (tree, score, "initial" or "checkpoint")."""
    if best_checkpoint["score"] > initial_score:
        return tree_from_json(best_checkpoint["tree"]), best_checkpoint["score"], "checkpoint"
    return initial, initial_score, "initial"
