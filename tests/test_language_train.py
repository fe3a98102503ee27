"""Training folds only see training data, and a tiny run learns simple trees."""

import dataclasses

import pytest
import torch

from nl2policy.language import evaluate
from nl2policy.language.augment import augment_fold, augment_text
from nl2policy.language.corpus import kfold, load_corpus
from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
from nl2policy.language.train import fit
from nl2policy.trees import to_tokens


def test_fold_training_data_reads_only_training_indices(monkeypatch):
    specs = load_corpus("taxi")
    train, test = next(kfold(specs, 5, seed=0))
    touched = []
    real_augment = evaluate.augment_fold

    def spy(specs_, idx, copies, seed=0):
        touched.extend(idx)
        return real_augment(specs_, idx, copies, seed)

    monkeypatch.setattr(evaluate, "augment_fold", spy)
    pairs = evaluate.fold_training_pairs("taxi", specs, train, DEFAULT_MODEL)
    assert touched and set(touched) <= set(train)
    test_texts = {specs[i].description for i in test}
    test_copies = {augment_text(specs[i].description, specs[i].id, c) for i in test for c in range(3)}
    texts = {t for t, _ in pairs}
    assert not texts & test_texts and not texts & test_copies


def test_augmentation_is_deterministic_and_changes_text():
    specs = load_corpus("highway")[:20]
    a = augment_fold(specs, range(20), 2)
    assert a == augment_fold(specs, range(20), 2)
    assert sum(t != specs[i // 2].description for i, (t, _) in enumerate(a)) >= 30
    assert [tree for _, tree in a] == [specs[i // 2].tree for i in range(40)]


def test_tiny_training_run_learns_two_simple_trees(one_torch_thread):
    torch.manual_seed(0)
    specs = load_corpus("taxi")
    wanted = {("has_passenger", "go_airport", "go_city"), ("heavy_traffic", "go_village", "go_city")}
    subset = [s for s in specs if tuple(to_tokens(s.tree)) in wanted]
    assert len(subset) == 16
    cfg = dataclasses.replace(MODELS["seq2tree"], epochs=25, hidden=32, embed=32, dropout=0.0, batch=8, aug_copies=0)
    pairs = [(s.description, s.tree) for s in subset]
    model = fit("taxi", "tiny", cfg, pairs, seed=0)
    assert model.history[-1] < model.history[0] / 4
    preds = [t for t, _ in model.predict([s.description for s in subset])]
    assert sum(p == s.tree for p, s in zip(preds, subset)) >= 14


def test_path_decoder_learns_two_simple_trees_and_outputs_valid_trees(one_torch_thread):
    """The path-conditioned node classifier (models/pathnet.py) trains and decodes valid trees."""
    from nl2policy.domains import get_domain
    from nl2policy.trees.parse import validate

    torch.manual_seed(0)
    specs = load_corpus("taxi")
    wanted = {("has_passenger", "go_airport", "go_city"), ("heavy_traffic", "go_village", "go_city")}
    subset = [s for s in specs if tuple(to_tokens(s.tree)) in wanted]
    cfg = dataclasses.replace(MODELS["pathnet-minilm"], minilm=False, epochs=25, hidden=32, embed=32, dropout=0.0,
                              batch=8, aug_copies=0)
    model = fit("taxi", "tiny-path", cfg, [(s.description, s.tree) for s in subset], seed=0)
    assert model.history[-1] < model.history[0] / 4
    results = model.predict([s.description for s in subset] + [s.description for s in specs[:30]])
    assert sum(t == s.tree for (t, _), s in zip(results, subset)) >= 14
    for tree, probs in results:
        validate(tree, get_domain("taxi").vocab)
        assert probs and all(0.0 <= p <= 1.0 for p in probs.values())


def test_learning_rate_decays_smoothly_from_base_to_floor():
    from nl2policy.language.train import _cosine_lr

    rates = [_cosine_lr(3e-3, step, 100) for step in range(101)]
    assert rates[0] == pytest.approx(3e-3)
    assert rates[-1] == pytest.approx(0.05 * 3e-3)
    assert all(a >= b for a, b in zip(rates, rates[1:]))
    assert _cosine_lr(3e-3, 500, 100) == pytest.approx(rates[-1])  # resuming past the end stays at the floor
