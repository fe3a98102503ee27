"""The learned findings: they learn which actions, questions and root a text names, and the
decoder's final choice and first step follow them."""

import dataclasses
import math

import pytest

from nl2policy.language.corpus import load_corpus
from nl2policy.language.findings import Findings, FindingsConfig, train_findings
from nl2policy.language.models.config import MODELS
from nl2policy.language.train import fit
from nl2policy.trees import parse_tree
from nl2policy.domains import get_domain

PLACES = ("airport", "village", "city")


def _pairs():
    vocab = get_domain("taxi").vocab
    out = []
    for place in PLACES:
        for other in PLACES:
            if other == place:
                continue
            text = f"If there is a passenger, drive to the {place}. Otherwise head to the {other}."
            tree = parse_tree({"if": "has_passenger", "yes": {"do": f"go_{place}"}, "no": {"do": f"go_{other}"}}, vocab)
            out.append((text, tree))
            text = f"Always drive to the {place}."
            out.append((text, parse_tree({"do": f"go_{place}"}, vocab)))
    return out


def test_findings_learn_the_actions_and_root_a_text_names(one_torch_thread):
    model = train_findings("taxi", _pairs(), seed=0, cfg=FindingsConfig(epochs=40, batch=4, dropout=0.0))
    read = model.read(["Always drive to the village.", "If there is a passenger, drive to the city. Otherwise head to the airport."])
    assert read[0].takes["go_village"] > 0.5 > read[0].takes["go_city"]
    assert max(read[0].root, key=read[0].root.get) == "go_village"
    assert read[1].asks["has_passenger"] > 0.5 and max(read[1].root, key=read[1].root.get) == "has_passenger"
    assert read[1].takes["go_city"] > 0.5 and read[1].takes["go_airport"] > 0.5 > read[1].takes["go_village"]
    # probabilities: the root's sum to one, and agreement is a log-probability
    assert math.isclose(sum(read[0].root.values()), 1.0, rel_tol=1e-5)
    tree = parse_tree({"do": "go_village"}, get_domain("taxi").vocab)
    assert read[0].log_agreement(tree) < 0 and read[0].log_agreement(tree) > read[1].log_agreement(tree)


class _Fixed:
    """A findings model that reads every text the same way."""

    def __init__(self, findings: Findings) -> None:
        self.findings = findings

    def read(self, texts):
        return [self.findings for _ in texts]


def test_decoding_follows_the_findings_root_and_actions(one_torch_thread):
    """With a large weight, the findings decide: the root is the one they put first, and the tree
    takes the actions they say it takes (every output still a valid tree)."""
    specs = load_corpus("taxi")
    vocab = get_domain("taxi").vocab
    cfg = dataclasses.replace(MODELS["smoke"], epochs=3, batch=16, beam=4)
    model = fit("taxi", "one", cfg, [(s.description, s.tree) for s in specs[:48]], seed=0)
    texts = [s.description for s in specs[48:60]]
    free = [t for t, _ in model.predict(texts)]
    labels = list(vocab.question_ids) + list(vocab.action_ids)
    wanted = Findings({q: 0.01 for q in vocab.question_ids}, {a: (0.99 if a == "wait" else 0.01) for a in vocab.action_ids},
                      {l: (0.99 if l == "wait" else 0.01 / (len(labels) - 1)) for l in labels})
    model.findings, model.findings_cost = _Fixed(wanted), 50.0
    steered = [t for t, _ in model.predict(texts)]
    assert all(t == parse_tree({"do": "wait"}, vocab) for t in steered)
    assert any(t != s for t, s in zip(free, steered))  # the smoke model alone does not say "wait" everywhere
    model.findings_cost = 0.0
    assert [t for t, _ in model.predict(texts)] == free


def test_a_batch_reads_and_decodes_each_text_as_it_reads_alone():
    """Padding must not leak into a text's reading: the lab decodes folds in batches, the product
    one text at a time, and both must give the same trees (the findings' BiGRU once read padding)."""
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.translate import get_model

    model = get_model("highway").translator
    texts = [s.description for s in load_corpus("highway", rounds=(2,))[:12]]
    together = model.read_findings(texts)
    for text, found in zip(texts, together):
        alone = model.read_findings([text])[0]
        assert all(abs(alone.asks[q] - found.asks[q]) < 1e-4 for q in alone.asks)
    assert [t for t, _ in model.predict(texts)] == [model.predict([t])[0][0] for t in texts]


def test_the_findings_train_for_the_warnings_where_decoding_gives_them_no_weight(one_torch_thread):
    """A recipe with `findings = true` and no findings cost (v6) trains them beside the networks,
    for translate's warnings; without either it trains none."""
    specs = load_corpus("taxi")
    pairs = [(s.description, s.tree) for s in specs[:24]]
    warned = dataclasses.replace(MODELS["smoke"], findings=True, findings_cost=0.0)
    assert fit("taxi", "one", warned, pairs, seed=0).findings is not None
    assert fit("taxi", "one", MODELS["smoke"], pairs, seed=0).findings is None
