"""What a translator trains on: one place that assembles a fold's training pairs.

The real descriptions of the training indices, then (as the model config asks) their augmented
copies and the synthetic pairs. Only
`train_idx` is ever read, so the cross-validation folds and the final model (all indices) are
built the same way.
"""

from __future__ import annotations

from typing import Callable, Sequence, Union

from nl2policy.language.augment import augment_fold
from nl2policy.language.corpus import Spec
from nl2policy.language.models.config import ModelConfig
from nl2policy.language.synthetic import synthetic_pairs
from nl2policy.trees import Tree


NoExclusion: Callable[[Tree], bool] = lambda tree: False


def training_pairs(domain: str, specs: Sequence[Spec], train_idx: Sequence[int], cfg: ModelConfig,
                   seed: int = 0, member: int = 0, exclude: Callable[[Tree], bool] = NoExclusion) -> list[tuple[str, Tree]]:
    """Ensemble member `member`'s pairs (it sets only how many synthetic pairs: ModelConfig.synthetic_for).
    `exclude`: trees no synthetic pair may have (an evaluation's held-out trees)."""
    pairs = [(specs[i].description, specs[i].tree) for i in train_idx]
    pairs += augment_fold(specs, train_idx, cfg.aug_copies, seed)
    synthetic = cfg.synthetic_for(member)
    if synthetic:
        pairs += synthetic_pairs(domain, synthetic, seed, [specs[i].tree for i in train_idx], exclude=exclude)
    return pairs


def member_pairs(domain: str, specs: Sequence[Spec], train_idx: Sequence[int], cfg: ModelConfig,
                 seed: int = 0, exclude: Callable[[Tree], bool] = NoExclusion) -> Union[list[tuple[str, Tree]], Callable[[int], list[tuple[str, Tree]]]]:
    """What `train.fit` gets: one list for every member, or with `cfg.member_draws` a function
    giving member m its own draw (augmentation and synthetic pairs seeded seed + m; the real
    descriptions are the same), so the ensemble's members also differ in what they read.
    `cfg.seed_offset` shifts every draw (and train.fit every member's initial weights)."""
    seed += cfg.seed_offset
    if not cfg.member_draws or cfg.ensemble == 1:
        return training_pairs(domain, specs, train_idx, cfg, seed, exclude=exclude)
    return lambda member: training_pairs(domain, specs, train_idx, cfg, seed + member, member, exclude)
