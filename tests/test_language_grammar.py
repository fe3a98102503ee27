"""Grammar-constrained decoding: every output is a valid tree, even from an untrained model."""

import random

import pytest
import torch

from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.grammar import allowed_tokens, next_slot
from nl2policy.language.models.config import MODELS
from nl2policy.language.models.network import build_network
from nl2policy.language.text import WordVocab
from nl2policy.language.translator import TrainedTranslator
from nl2policy.trees import from_tokens, to_tokens
from nl2policy.trees.parse import validate

pytestmark = pytest.mark.usefixtures("one_torch_thread")



def test_no_branch_may_not_copy_its_yes_sibling():
    vocab = get_domain("taxi").vocab
    slot = next_slot(["has_passenger", "at_city", "wait", "go_city", "at_city", "wait"], vocab)
    assert slot.forbidden == {"wait", "go_city"}
    assert set(allowed_tokens(slot, vocab)) == {"go_airport", "go_village", "at_airport", "at_village", "heavy_traffic", "long_wait"}
    deep = next_slot(["has_passenger", "at_city", "long_wait"], vocab)  # depth 3: actions only
    assert set(allowed_tokens(deep, vocab)) == {"go_airport", "go_village", "go_city", "wait"}


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_random_walks_through_the_grammar_always_end_in_valid_trees(domain):
    vocab = get_domain(domain).vocab
    rng = random.Random(0)
    for _ in range(300):
        prefix = []
        while (slot := next_slot(prefix, vocab)) is not None:
            prefix.append(rng.choice(allowed_tokens(slot, vocab)))
        validate(from_tokens(prefix, vocab), vocab)


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_every_gold_tree_is_allowed_by_the_grammar(domain):
    vocab = get_domain(domain).vocab
    for spec in load_corpus(domain):
        tokens = to_tokens(spec.tree)
        for t, tok in enumerate(tokens):
            assert tok in allowed_tokens(next_slot(tokens[:t], vocab), vocab)
        assert next_slot(tokens, vocab) is None


@pytest.mark.parametrize("name", ["seq2seq", "han2tree", "seq2tree-minilm"])
def test_untrained_models_output_valid_trees_for_every_description(name):
    """The paper's baselines (the lab's architectures, decoded by the product's beam search) too."""
    import experiments.translation.baselines  # noqa: F401  (registers them)

    torch.manual_seed(0)
    domain = "highway"
    specs = load_corpus(domain)
    vocab = get_domain(domain).vocab
    words = WordVocab.build([s.description for s in specs])
    net = build_network(MODELS[name], len(words), len(vocab.question_ids) + len(vocab.action_ids))
    model = TrainedTranslator(domain, name, MODELS[name], words, [net])
    texts = [s.description for s in specs] if name != "seq2tree-minilm" else [s.description for s in specs[::10]]
    outputs = model.predict(texts)
    assert len(outputs) == len(texts)
    for tree, probs in outputs:
        validate(tree, vocab)
        assert all(0.0 <= p <= 1.0 for p in probs.values())
