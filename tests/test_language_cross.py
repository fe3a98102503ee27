"""Training on the other domain's descriptions too (ModelConfig.other_domains)."""

import dataclasses

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.augment import augment_text
from nl2policy.language.corpus import kfold, load_corpus
from nl2policy.language.dataset import borrowed_pairs, training_pairs
from nl2policy.language.grammar import allowed_tokens, next_slot
from nl2policy.language.models.config import MODELS
from nl2policy.language.train import fit, gold_steps, tree_domain
from nl2policy.trees import Leaf, Node, to_tokens
from nl2policy.trees.parse import validate

CROSS = "seq2tree-minilm-synth-cross-x4-mentions"


def test_borrowed_pairs_are_the_other_domains_descriptions_by_the_training_writers_only():
    highway = load_corpus("highway")
    writers = {"careful", "coder", "texter"}
    pairs = borrowed_pairs("taxi", writers, aug_copies=1, seed=0)
    mine = [s for s in highway if s.writer in writers]
    assert len(pairs) == 2 * len(mine) == 150
    texts = [t for t, _ in pairs]
    assert texts[: len(mine)] == [s.description for s in mine]
    assert texts[len(mine):] == [augment_text(s.description, s.id, 0, 0) for s in mine]
    others = {s.description for s in highway if s.writer not in writers}
    assert not set(texts) & others
    assert all(tree_domain(tree, ["taxi", "highway"]) == "highway" for _, tree in pairs)


def test_leave_writers_out_folds_borrow_nothing_from_the_held_out_writers():
    specs = load_corpus("taxi")
    train, test = next(kfold(specs, 4, seed=0, by_writer=True))
    held_out = {specs[i].writer for i in test}
    pairs = training_pairs("taxi", specs, train, MODELS[CROSS])
    texts = {t for t, _ in pairs}
    for domain in ("taxi", "highway"):
        theirs = [s for s in load_corpus(domain) if s.writer in held_out]
        assert theirs and not texts & {s.description for s in theirs}
        assert not texts & {augment_text(s.description, s.id, 0, 0) for s in theirs}
    assert training_pairs("taxi", specs, train, dataclasses.replace(MODELS[CROSS], other_domains=False)) == \
        pairs[: len(pairs) - len(borrowed_pairs("taxi", {specs[i].writer for i in train}, 1, 0))]


def test_a_borrowed_tree_is_taught_with_its_own_domains_grammar():
    names = get_domain("taxi").vocab.question_ids + get_domain("taxi").vocab.action_ids
    names += get_domain("highway").vocab.question_ids + get_domain("highway").vocab.action_ids
    tree = Node("car_ahead_close", Leaf("lane_left"), Leaf("faster"))
    targets, parents, branches, masks = gold_steps(tree, "highway", names)
    assert [names[t] for t in targets] == to_tokens(tree)
    vocab = get_domain("highway").vocab
    for t, mask in enumerate(masks):
        allowed = {n for n, ok in zip(names, mask) if ok}
        assert allowed == set(allowed_tokens(next_slot(to_tokens(tree)[:t], vocab), vocab))  # never a taxi label
    with pytest.raises(ValueError, match="none of"):
        tree_domain(tree, ["taxi"])


def test_the_domains_labels_are_disjoint():
    """tree_domain tells a borrowed tree's domain by its labels, and the decoder scores both label
    sets side by side: neither works if a question or action id were shared."""
    labels = [set(get_domain(d).vocab.question_ids + get_domain(d).vocab.action_ids) for d in ("taxi", "highway")]
    assert labels[0] and labels[1] and not labels[0] & labels[1]


def test_a_cross_domain_model_scores_both_label_sets_and_outputs_only_its_own_domains_trees(one_torch_thread):
    cfg = dataclasses.replace(MODELS[CROSS], epochs=3, ensemble=2, synthetic=10, hidden=32, embed=32, minilm=False)
    specs = load_corpus("taxi")
    train = [i for i, s in enumerate(specs) if s.writer in ("careful", "coder")][:30]
    pairs = training_pairs("taxi", specs, train, cfg)
    model = fit("taxi", "cross-tiny", cfg, pairs, seed=0, vocab_texts=[specs[i].description for i in train])
    assert len(model.tree_tokens) == 10 + 12 and model.tree_tokens[:10] == \
        get_domain("taxi").vocab.question_ids + get_domain("taxi").vocab.action_ids
    assert model.net.logits.out_features == 22
    texts = [s.description for s in specs[100:110]] + [s.description for s in load_corpus("highway")[:5]]
    for tree, _ in model.predict(texts):
        validate(tree, get_domain("taxi").vocab)  # even a highway text gets a taxi tree
