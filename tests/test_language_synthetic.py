"""The synthetic (description, tree) generator: valid trees, every branch told, reproducible."""

import random

import pytest

from nl2policy.domains import get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.synthetic import describe, random_tree, synthetic_pairs
from nl2policy.trees import Leaf, Node, to_tokens
from nl2policy.trees.parse import validate


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_random_trees_are_valid_and_varied(domain):
    vocab = get_domain(domain).vocab
    rng = random.Random(0)
    trees = [random_tree(vocab, rng) for _ in range(300)]
    for t in trees:
        validate(t, vocab)
        assert not isinstance(t, Leaf)
    assert len({tuple(to_tokens(t)) for t in trees}) > 250
    depths = {max(len(p) for p in _paths(t)) for t in trees}
    assert depths == {1, 2, 3}


def _paths(tree, path=()):
    if isinstance(tree, Leaf):
        return [path]
    return _paths(tree.yes, path + (tree.question,)) + _paths(tree.no, path + (tree.question,))


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_every_phrase_set_is_complete(domain):
    vocab = get_domain(domain).vocab
    phrases = get_domain(domain).phrases  # the domain's own (domains/phrases/DOMAIN.toml)
    assert set(phrases["questions"]) == set(vocab.question_ids)
    assert set(phrases["actions"]) == set(vocab.action_ids) == set(phrases["reasons"])
    for q in phrases["questions"].values():
        assert all(q[k] for k in ("pos", "neg", "short", "short_no"))


def test_pseudo_code_names_are_made_from_the_question_id_alone():
    """No name a writer invented: each is the id, re-cased ("hasPassenger", "HAS_PASSENGER")."""
    from nl2policy.language.phrases import code_names

    assert code_names("has_passenger") == ["has_passenger", "hasPassenger", "HasPassenger", "HAS_PASSENGER",
                                           "isHasPassenger"]
    for domain in ("taxi", "highway"):
        for q in get_domain(domain).vocab.question_ids:
            assert all(name.lower().replace("_", "").endswith(q.replace("_", "")) for name in code_names(q))


def test_pairs_are_reproducible_and_describe_training_trees_per_tree_times():
    vocab = get_domain("highway").vocab
    extra = [random_tree(vocab, random.Random(9)) for _ in range(5)]
    a = synthetic_pairs("highway", 20, seed=3, extra_trees=extra, per_tree=2)
    assert a == synthetic_pairs("highway", 20, seed=3, extra_trees=extra, per_tree=2)
    assert len(a) == 30 and [t for _, t in a[20:]] == [t for t in extra for _ in range(2)]
    assert a[20][0] != a[21][0]  # two wordings of one tree
    assert all(text.strip() for text, _ in a)


def test_descriptions_mention_every_action_of_the_tree():
    """Every leaf is said in words (asides may mention more, never fewer)."""
    rng = random.Random(4)
    vocab = get_domain("taxi").vocab
    for _ in range(200):
        tree = random_tree(vocab, rng)
        text = describe(tree, "taxi", rng).lower()
        for action in {t for t in to_tokens(tree) if t in vocab.action_ids}:
            assert any(_loose(p) in text for p in get_domain("taxi").phrases["actions"][action]), (action, text)


def _loose(s: str) -> str:
    """Texting and dropped articles change words; compare on the distinctive last word."""
    return s.lower().split()[-1]
