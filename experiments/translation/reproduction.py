"""Which folds reproduce which: a fold retrains bit for bit only on the kind of CPU that first
ran it, so before the report sets two machines' folds side by side it checks, on folds whose
networks two models both recorded, that the machines agree (see results/translation/README.md).

A fold of a model decoded with more checks also records the same networks decoded with less of
them (evaluate.DECODING_ALTERNATIVES); where that is exactly another model's config, that
model's own fold retrained those networks and must score the same: the reproduction check.
"""

from __future__ import annotations

from dataclasses import replace

from experiments.translation.evaluate import DECODING_ALTERNATIVES
from nl2policy.language.models.config import MODELS, ModelConfig


NOT_RECORDED = "not recorded"
"""The machine of a fold recorded before folds carried theirs (see results/translation/README.md)."""


def fold_machine(run: dict) -> str:
    """The CPU a fold trained on, as recorded (NOT_RECORDED for the earliest folds)."""
    return run.get("machine", NOT_RECORDED)


MIN_REPRODUCED = 5
"""Folds on which two kinds of CPU must have trained the same networks, agreeing on every one,
before the paired tables set one's folds beside the other's."""


def reproduction_checks(runs: list[dict]) -> dict[tuple[str, str], tuple[int, int]]:
    """Do two records of the same networks on the same fold agree? A fold of model Y records its
    networks decoded with less of a choice (DECODING_ALTERNATIVES); where that is exactly model X's
    config (Y = seq2tree-minilm-synth-x6-mentions with its first four members: X =
    seq2tree-minilm-synth-x4-mentions), X's own fold of the same domain retrained those networks and
    must score the same. Per pair of machines (sorted): (folds whose tree accuracy agrees, folds).
    On one machine this checks that training is deterministic; across two, whether they are one
    kind of CPU as far as training goes (the earlier machine never recorded its kind)."""
    index = {(r["domain"], r["model"], r["fold"]): r for r in runs}
    checks: dict[tuple[str, str], tuple[int, int]] = {}
    for r in runs:
        if "networks_from" in r:  # decoded another model's saved networks: no retraining to check
            continue
        for key in DECODING_ALTERNATIVES:
            if key not in r:
                continue
            for other in decoded_as(r["model"], key):
                if (o := index.get((r["domain"], other, r["fold"]))) is not None:
                    pair = tuple(sorted((fold_machine(r), fold_machine(o))))
                    agree, n = checks.get(pair, (0, 0))
                    checks[pair] = (agree + (o["tree_acc"] == r[key]), n + 1)
    return checks


def decoded_as(model: str, key: str) -> list[str]:
    """The models whose config is exactly `model` decoded with less of one choice
    (DECODING_ALTERNATIVES[key]): seq2tree-minilm-synth-x6-mentions with its first four members
    is seq2tree-minilm-synth-x4-mentions. Such a model's own fold trains the same networks."""
    if model not in MODELS:
        return []
    attr, off, _ = DECODING_ALTERNATIVES[key]
    target = _decodes_as(replace(MODELS[model], **{attr: off}))
    return [name for name, cfg in MODELS.items() if _decodes_as(cfg) == target]


def _decodes_as(cfg: ModelConfig) -> ModelConfig:
    """`cfg` with the settings that change nothing set to their defaults: without a question check,
    which patterns it would use; without a rule check, which statements it would read."""
    if not cfg.question_cost:
        cfg = replace(cfg, question_forms=ModelConfig.question_forms)
    return cfg if cfg.rule_cost else replace(cfg, rule_forms=ModelConfig.rule_forms)


def machine_kinds(checks: dict[tuple[str, str], tuple[int, int]], labels: dict[str, str]) -> dict[str, str]:
    """Each machine -> the first-labelled machine it reproduces (itself if none): two machines are
    one kind when their checks agree on every fold, and on at least MIN_REPRODUCED."""
    kind = {m: m for m in labels}
    for (a, b), (agree, n) in _in_label_order(checks, labels):
        if a != b and agree == n >= MIN_REPRODUCED:
            first, second = sorted((kind[a], kind[b]), key=lambda m: labels[m])
            kind = {m: first if k == second else k for m, k in kind.items()}
    return kind


def _in_label_order(checks: dict[tuple[str, str], tuple[int, int]], labels: dict[str, str]) -> list:
    """The checks sorted by their machines' labels (A with A, A with B, ...). Both come from the
    same folds, so every machine a check names has a label."""
    return sorted(checks.items(), key=lambda c: sorted(labels[m] for m in c[0]))


def machine_labels(runs: list[dict]) -> dict[str, str]:
    """A short label per kind of CPU (A, B, ...), in the order the folds first name them: the
    tables say which machine trained each row, since folds reproduce only on one kind."""
    labels: dict[str, str] = {}
    for r in runs:
        labels.setdefault(fold_machine(r), chr(ord("A") + len(labels)))
    return labels


def reproduction_lines(checks: dict[tuple[str, str], tuple[int, int]], kinds: dict[str, str],
                       labels: dict[str, str]) -> list[str]:
    """The report's line on the checks: per pair of machines, folds agreeing of folds checked, and
    which machines count as one kind (machine_kinds)."""
    if not checks:
        return []
    same = sorted({f"{labels[m]} = {labels[k]}" for m, k in kinds.items() if m != k})
    return ["Reproduction checks (one fold's networks recorded by two models, e.g. a model's first four "
            "members and the four-member model's own fold; folds whose tree accuracy agrees): "
            + "; ".join(" with ".join(sorted(labels[m] for m in pair)) + f" {agree} of {n}"
                        for pair, (agree, n) in _in_label_order(checks, labels))
            + ". " + (f"Counted as one kind of CPU in the paired tables (all of at least {MIN_REPRODUCED} agree): "
                      + ", ".join(same) + "." if same else "")]
