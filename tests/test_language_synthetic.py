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
    trees = [random_tree(get_domain(domain), rng) for _ in range(300)]
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
    phrases = get_domain(domain).phrases  # the domain's own (domains/DOMAIN/phrases.toml)
    assert set(phrases["questions"]) == set(vocab.question_ids)
    assert set(phrases["actions"]) == set(vocab.action_ids) == set(phrases["reasons"])
    for q in phrases["questions"].values():
        assert all(q[k] for k in ("pos", "neg", "short", "short_no"))


def test_pseudo_code_names_are_made_from_the_question_id_alone():
    """No name a writer invented: each is the id, re-cased ("hasPassenger", "HAS_PASSENGER")."""
    from nl2policy.language.synthetic import code_names

    assert code_names("has_passenger") == ["has_passenger", "hasPassenger", "HasPassenger", "HAS_PASSENGER",
                                           "isHasPassenger"]
    for domain in ("taxi", "highway"):
        for q in get_domain(domain).vocab.question_ids:
            assert all(name.lower().replace("_", "").endswith(q.replace("_", "")) for name in code_names(q))


def test_pairs_are_reproducible_and_describe_training_trees_per_tree_times():
    extra = [random_tree(get_domain("highway"), random.Random(9)) for _ in range(5)]
    a = synthetic_pairs("highway", 20, seed=3, extra_trees=extra, per_tree=2)
    assert a == synthetic_pairs("highway", 20, seed=3, extra_trees=extra, per_tree=2)
    assert len(a) == 30 and [t for _, t in a[20:]] == [t for t in extra for _ in range(2)]
    assert a[20][0] != a[21][0]  # two wordings of one tree
    assert all(text.strip() for text, _ in a)


def test_descriptions_mention_every_action_of_the_tree():
    """Every leaf is said in words (asides may mention more, never fewer)."""
    rng = random.Random(4)
    vocab = get_domain("taxi").vocab
    for _ in range(300):
        tree = random_tree(get_domain("taxi"), rng)
        text = describe(tree, "taxi", rng, typo_rate=0.0).lower()
        for action in {t for t in to_tokens(tree) if t in vocab.action_ids}:
            assert any(_loose(p) in text for p in get_domain("taxi").phrases["actions"][action]), (action, text)


def _loose(s: str) -> str:
    """Texting and dropped articles change words; compare on the distinctive last word."""
    return s.lower().split()[-1]


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_random_trees_follow_the_size_mix_with_shapes_uniform_within_a_size(domain):
    """Round 2's sampling (corpus/round2/README): 15 / 25 / 30 % with 1 / 2 / 3 questions, 30 % with
    4-7, every shape of a size equally often (4-7 pooled)."""
    from collections import Counter

    from nl2policy.language.synthetic.trees import SIZE_MIX, shapes_by_size

    assert {n: len(s) for n, s in shapes_by_size().items()} == {1: 1, 2: 2, 3: 5, 4: 6, 5: 6, 6: 4, 7: 1}
    rng = random.Random(1)
    trees = [random_tree(get_domain(domain), rng) for _ in range(3000)]
    sizes = Counter(sum(1 for t in to_tokens(tree) if t in get_domain(domain).vocab.question_ids) for tree in trees)
    for size, share in SIZE_MIX:
        got = sum(sizes[n] for n in (size if isinstance(size, tuple) else (size,))) / len(trees)
        assert abs(got - share) < 0.03, (size, got, share)
    big = sizes[7] / len(trees)  # 1 shape of the 17 with 4-7 questions
    assert abs(big - 0.30 / 17) < 0.01


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_random_trees_never_ask_a_question_the_path_already_answers(domain):
    d = get_domain(domain)
    rng = random.Random(2)

    def check(tree, answered):
        if isinstance(tree, Leaf):
            return
        assert tree.question not in answered and d.forced_answer(answered, tree.question) is None
        assert tree.yes != tree.no
        check(tree.yes, {**answered, tree.question: True})
        check(tree.no, {**answered, tree.question: False})

    for _ in range(500):
        check(random_tree(d, rng), {})


@pytest.mark.parametrize("style", ["nested", "rules", "default", "chain", "outline", "qa", "table", "code", "arrows", "memo"])
def test_every_style_describes_every_shape_and_says_every_action(style):
    rng = random.Random(5)
    d = get_domain("highway")
    for _ in range(60):
        tree = random_tree(d, rng)
        text = describe(tree, "highway", rng, style=style, typo_rate=0.0).lower()
        assert text.strip()
        for action in {t for t in to_tokens(tree) if t in d.vocab.action_ids}:
            assert any(_loose(p) in text for p in d.phrases["actions"][action]), (style, action, text)


def test_the_general_lexicon_names_no_domain_word():
    """english.toml is domain-free: none of a domain's question or action words is in it."""
    from nl2policy.language.synthetic.words import english

    text = repr(english()).lower()  # its entries, not its comments
    for domain in ("taxi", "highway"):
        for q in get_domain(domain).vocab.question_ids + get_domain(domain).vocab.action_ids:
            for part in q.split("_"):
                if len(part) > 5:  # (not "ahead": "go ahead and ..." is anyone's English)
                    assert part not in text, (domain, part)



def test_styles_limits_every_style_a_description_uses_and_an_empty_choice_is_an_error(monkeypatch):
    """Leave-style-out trains on some styles only: a held-out style must not come back through
    the closing summary (written as arrows or rules) either."""
    import functools

    import nl2policy.language.synthetic as gen

    used: list[str] = []

    def recording(f):
        @functools.wraps(f)
        def wrapper(*args, **kwargs):
            used.append(f.__name__)
            return f(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(gen, "STYLES", {k: recording(f) for k, f in gen.STYLES.items()})
    monkeypatch.setattr(gen, "arrows", recording(gen.arrows))
    monkeypatch.setattr(gen, "rules", recording(gen.rules))
    tree = get_domain("taxi").example_tree
    rng = random.Random(0)
    for _ in range(300):
        describe(tree, "taxi", rng, styles={"qa", "rules"})
    assert set(used) == {"qa", "rules"}  # both drawn, summaries included; arrows (a summary form) never
    used.clear()
    assert len(synthetic_pairs("taxi", 50, 0, styles={"nested"})) == 50 and set(used) == {"nested"}
    with pytest.raises(ValueError, match="no style"):
        describe(tree, "taxi", rng, styles=set())
