"""MiniLM's top layers trained with the translator (ModelConfig.minilm_tune)."""

import dataclasses
import math

import pytest
import torch

from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.models.config import MODELS
from nl2policy.language.text import WordVocab
from nl2policy.language.train import TrainedTranslator, _cosine_lr, collate, fit
from nl2policy.trees.parse import validate


def _translator(cfg, specs):
    return TrainedTranslator("taxi", "t", cfg, WordVocab.build([s.description for s in specs]), [])


def test_a_fresh_tuned_layer_recomputes_the_cached_layer_it_replaces(one_torch_thread):
    """At the start of training the tuned copy of MiniLM's last layer, fed the cached layer below
    it (our tokens standing in for word pieces), gives nearly the cached last layer: training
    starts from the pretrained features, not from a broken copy. Without tuning the cached
    layers pass through untouched."""
    specs = load_corpus("taxi")[:12]
    base = MODELS["seq2tree-minilm-synth-x4-mentions"]
    tuned = _translator(dataclasses.replace(base, minilm_tune=1), specs)
    batch = collate([tuned.encode(s.description) for s in specs])
    with torch.inference_mode():
        states = tuned.new_net().eval()._minilm_states(batch)
        frozen = _translator(base, specs).new_net().eval()._minilm_states(batch)
    assert frozen is batch.mini
    assert states.shape == batch.mini.shape
    assert torch.equal(states[:, :-1], batch.mini[:, :-1])
    mask = batch.words != 0
    same = torch.nn.functional.cosine_similarity(states[:, -1][mask], batch.mini[:, -1][mask], -1)
    below = torch.nn.functional.cosine_similarity(batch.mini[:, -2][mask], batch.mini[:, -1][mask], -1)
    assert same.mean() > 0.95 > below.mean() + 0.2  # much nearer the layer it replaces than its input is


def test_the_tuned_layer_trains_at_its_own_rate(monkeypatch, one_torch_thread):
    specs = load_corpus("taxi")[:16]
    cfg = dataclasses.replace(MODELS["smoke"], minilm=True, minilm_layers=1, minilm_tune=1, epochs=2, batch=8,
                              minilm_lr=2e-4)
    optimizers = []
    real_adam = torch.optim.Adam

    def recording_adam(*args, **kwargs):
        optimizers.append(real_adam(*args, **kwargs))
        return optimizers[-1]

    monkeypatch.setattr(torch.optim, "Adam", recording_adam)
    model = fit("taxi", "t", cfg, [(s.description, s.tree) for s in specs], seed=0)
    opt, net = optimizers[-1], model.net
    # fit hands back fresh networks loaded with the trained weights: compare values, not objects
    tuned = list(net.mini_top.parameters())
    assert len(opt.param_groups[1]["params"]) == len(tuned)
    assert all(torch.equal(a, b) for a, b in zip(opt.param_groups[1]["params"], tuned))
    assert len(opt.param_groups[0]["params"]) + len(opt.param_groups[1]["params"]) == len(list(net.parameters()))
    steps = cfg.epochs * math.ceil(len(specs) / cfg.batch)
    assert opt.param_groups[0]["lr"] == pytest.approx(_cosine_lr(cfg.lr, steps - 1, steps))
    assert opt.param_groups[1]["lr"] == pytest.approx(_cosine_lr(2e-4, steps - 1, steps))
    fresh = _translator(cfg, specs).new_net()
    moved = [not torch.equal(a, b) for a, b in zip(net.mini_top.parameters(), fresh.mini_top.parameters())]
    assert all(moved)


def test_an_empty_text_still_decodes_with_a_tuned_layer(one_torch_thread):
    specs = load_corpus("taxi")[:8]
    cfg = dataclasses.replace(MODELS["smoke"], minilm=True, minilm_layers=1, minilm_tune=1, epochs=1, batch=8)
    model = fit("taxi", "t", cfg, [(s.description, s.tree) for s in specs], seed=0)
    [(tree, probs)] = model.predict([""])
    validate(tree, get_domain("taxi").vocab)
    assert all(0 < p <= 1 for p in probs.values())


def test_tuning_more_layers_than_are_run_is_refused():
    cfg = dataclasses.replace(MODELS["smoke"], minilm=True, minilm_layers=1, minilm_tune=2)
    with pytest.raises(ValueError, match="minilm_tune"):
        _translator(cfg, load_corpus("taxi")[:2]).new_net()
