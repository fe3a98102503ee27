"""Training folds only see training data, and a tiny run learns simple trees."""

import copy
import dataclasses
import math

import pytest
import torch

from nl2policy.language.augment import augment_fold, augment_text
from nl2policy.language.corpus import kfold, load_corpus
from nl2policy.language import dataset
from nl2policy.language.dataset import training_pairs
from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
from nl2policy.language.train import fit
from nl2policy.trees import to_tokens

pytestmark = pytest.mark.train


@pytest.mark.parametrize("name", [DEFAULT_MODEL, "smoke"])
def test_fold_training_data_reads_only_training_indices(monkeypatch, name):
    specs = load_corpus("taxi")
    train, test = next(kfold(specs, 5, seed=0))
    touched = []
    real_augment = dataset.augment_fold

    def spy(specs_, idx, copies, seed=0):
        touched.extend(idx)
        return real_augment(specs_, idx, copies, seed)

    monkeypatch.setattr(dataset, "augment_fold", spy)
    pairs = training_pairs("taxi", specs, train, MODELS[name])
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
    cfg = dataclasses.replace(MODELS["smoke"], epochs=25, hidden=32, embed=32, dropout=0.0, batch=8, aug_copies=0)
    pairs = [(s.description, s.tree) for s in subset]
    model = fit("taxi", "tiny", cfg, pairs, seed=0)
    assert model.history[-1] < model.history[0] / 4
    preds = [t for t, _ in model.predict([s.description for s in subset])]
    assert sum(p == s.tree for p, s in zip(preds, subset)) >= 14


def test_learning_rate_decays_smoothly_from_base_to_floor():
    from nl2policy.language.train import _cosine_lr

    rates = [_cosine_lr(3e-3, step, 100) for step in range(101)]
    assert rates[0] == pytest.approx(3e-3)
    assert rates[-1] == pytest.approx(0.05 * 3e-3)
    assert all(a >= b for a, b in zip(rates, rates[1:]))
    assert _cosine_lr(3e-3, 500, 100) == pytest.approx(rates[-1])  # resuming past the end stays at the floor


def test_length_batches_cover_every_item_once_and_group_similar_lengths():
    import random

    from nl2policy.language.train import _length_batches

    lengths = [random.Random(1).randint(5, 300) for _ in range(1000)]
    batches = _length_batches(lengths, 32, random.Random(0))
    assert sorted(i for b in batches for i in b) == list(range(1000))
    spread = sum(max(lengths[i] for i in b) - min(lengths[i] for i in b) for b in batches) / len(batches)
    assert spread < 60  # random batches of 32 from 5..300 spread over ~270
    assert _length_batches(lengths, 32, random.Random(0)) == batches


def test_ensemble_averages_members_and_resumes_from_a_checkpoint(one_torch_thread):
    """Two members: decoding averages them; a run stopped after the first member's last
    epoch resumes to the same networks as an uninterrupted run."""
    specs = load_corpus("taxi")
    wanted = {("has_passenger", "go_airport", "go_city"), ("heavy_traffic", "go_village", "go_city")}
    subset = [s for s in specs if tuple(to_tokens(s.tree)) in wanted]
    cfg = dataclasses.replace(MODELS["smoke"], epochs=12, batch=8, lr=1e-2, ensemble=2)
    pairs = [(s.description, s.tree) for s in subset]
    checkpoints = []  # what a checkpoint file would hold: a snapshot at that epoch
    full = fit("taxi", "ens", cfg, pairs, seed=0, on_epoch=lambda c: checkpoints.append(copy.deepcopy(c)))
    # one checkpoint after each epoch of each member, and one as each member finishes
    assert len(full.nets) == 2 and len(checkpoints) == 26
    assert [sorted(c["partial"]) for c in checkpoints] == [[0]] * 12 + [[]] + [[1]] * 12 + [[]]
    assert [sorted(c["finished"]) for c in checkpoints] == [[]] * 12 + [[0]] * 13 + [[0, 1]]
    assert checkpoints[16]["partial"][1]["epoch"] == 4
    a, b = (list(n.parameters())[-1] for n in full.nets)
    assert not torch.equal(a, b)  # different seeds, different members
    resumed = fit("taxi", "ens", cfg, pairs, seed=0, state=checkpoints[16])  # member 1 after epoch 4
    for n1, n2 in zip(full.nets, resumed.nets):
        for p1, p2 in zip(n1.parameters(), n2.parameters()):
            assert torch.equal(p1, p2)
    assert resumed.history == full.history
    from nl2policy.domains import get_domain
    from nl2policy.language.grammar import allowed_tokens, next_slot
    from nl2policy.language.translator import collate

    texts = [s.description for s in subset[:8]]
    vocab = get_domain("taxi").vocab
    root_ok = torch.tensor([t in allowed_tokens(next_slot([], vocab), vocab) for t in full.tree_tokens])
    with torch.inference_mode():
        batch = collate([full.encode(t) for t in texts])
        root = []  # each member's distribution over the root's allowed tokens
        for net in full.nets:
            memory = net.encode(batch)
            B = len(texts)
            _, _, logits = net.run_step(memory, [memory["h0"]], [torch.zeros(B, net.out.in_features - cfg.hidden)],
                                        [torch.full((B,), net.start_id)], torch.full((B,), -1), torch.zeros(B, dtype=torch.long))
            root.append(torch.softmax(logits.masked_fill(~root_ok, -1e9), -1))
    mean = (root[0] + root[1]) / 2
    for i, (tree, probs) in enumerate(full.predict(texts)):
        token = to_tokens(tree)[0]
        assert token == full.tree_tokens[int(mean[i].argmax())]  # the ensemble picks the averaged argmax
        assert probs[0] == pytest.approx(float(mean[i].max()), abs=1e-5)


def test_members_trained_in_worker_processes_equal_members_trained_one_by_one(one_torch_thread):
    """Each member depends only on its seed and its draw, so forked workers (one thread each)
    give the same networks; their checkpoints come back to the parent and resume there."""
    specs = load_corpus("taxi")[:24]
    cfg = dataclasses.replace(MODELS["smoke"], epochs=3, ensemble=3)
    draws = {m: [(s.description, s.tree) for s in specs[m:m + 20]] for m in range(3)}  # each member its own draw
    progress, checkpoints = [], []
    one_by_one = fit("taxi", "w", cfg, draws.__getitem__, seed=5)
    forked = fit("taxi", "w", cfg, draws.__getitem__, seed=5, workers=2, progress=lambda d, t: progress.append((d, t)),
                 on_epoch=lambda c: checkpoints.append(copy.deepcopy(c)))
    for n1, n2 in zip(one_by_one.nets, forked.nets, strict=True):
        for p1, p2 in zip(n1.parameters(), n2.parameters()):
            assert torch.equal(p1, p2)
    assert forked.history == one_by_one.history
    assert progress[-1][0] == progress[-1][1] and len(checkpoints) == 3 * 3 + 3
    assert sorted(checkpoints[-1]["finished"]) == [0, 1, 2] and not checkpoints[-1]["partial"]
    interrupted = next(c for c in checkpoints if c["partial"].get(2, {}).get("epoch") == 1)
    resumed = fit("taxi", "w", cfg, draws.__getitem__, seed=5, workers=2, state=interrupted)
    for n1, n2 in zip(one_by_one.nets, resumed.nets):
        for p1, p2 in zip(n1.parameters(), n2.parameters()):
            assert torch.equal(p1, p2)


def test_findings_trained_beside_the_forked_members_equal_findings_trained_after_them(one_torch_thread):
    """With workers, the learned findings train as one more job of the members' pool (no core
    idles while they train at the end); they come out the same as trained in the parent."""
    specs = load_corpus("taxi")[:16]
    cfg = dataclasses.replace(MODELS["smoke"], epochs=1, ensemble=2, findings_cost=1.0)
    pairs = [(s.description, s.tree) for s in specs]
    inline, forked = fit("taxi", "f", cfg, pairs, seed=2), fit("taxi", "f", cfg, pairs, seed=2, workers=2)
    got, want = forked.findings.state()["net"], inline.findings.state()["net"]
    assert got.keys() == want.keys() and all(torch.equal(got[k], want[k]) for k in want)
    assert forked.findings.cache is forked.cache  # it reads new texts through the model's own cache


def test_a_failing_worker_stops_training_with_its_error(one_torch_thread):
    specs = load_corpus("taxi")[:10]
    cfg = dataclasses.replace(MODELS["smoke"], ensemble=2)

    def draw(member):
        if member == 1:
            raise ValueError("no pairs for member 1")
        return [(s.description, s.tree) for s in specs]

    with pytest.raises(RuntimeError, match="member 1 failed: ValueError: no pairs for member 1"):
        fit("taxi", "w", cfg, draw, workers=2)


def test_training_is_reproducible_from_the_seed(one_torch_thread):
    specs = load_corpus("taxi")[:24]
    cfg = dataclasses.replace(MODELS["smoke"], epochs=2)
    pairs = [(s.description, s.tree) for s in specs]
    a = fit("taxi", "r", cfg, pairs, seed=3)
    torch.rand(5)  # unrelated draws from the global generator must not matter
    b = fit("taxi", "r", cfg, pairs, seed=3)
    for p1, p2 in zip(a.net.parameters(), b.net.parameters()):
        assert torch.equal(p1, p2)


def test_a_seed_offset_is_another_training_run_of_the_same_recipe(one_torch_thread):
    """seed_offset k trains what seed + k trains (weights and draws alike), and differs from seed."""
    from nl2policy.language.dataset import member_pairs

    specs = load_corpus("taxi")[:30]
    cfg = dataclasses.replace(MODELS["smoke"], epochs=1, ensemble=2, synthetic=10, member_draws=True)
    shifted = dataclasses.replace(cfg, seed_offset=5)
    draws = lambda c, seed: member_pairs("taxi", specs, range(30), c, seed)
    assert [draws(shifted, 0)(m) for m in (0, 1)] == [draws(cfg, 5)(m) for m in (0, 1)] != [draws(cfg, 0)(m) for m in (0, 1)]
    a, b, c = fit("taxi", "s", shifted, draws(shifted, 0), seed=0), fit("taxi", "s", cfg, draws(cfg, 5), seed=5), \
        fit("taxi", "s", cfg, draws(cfg, 0), seed=0)
    for na, nb, nc in zip(a.nets, b.nets, c.nets):
        assert all(torch.equal(p, q) for p, q in zip(na.parameters(), nb.parameters()))
        assert not all(torch.equal(p, q) for p, q in zip(na.parameters(), nc.parameters()))


def test_stacked_decoder_step_equals_each_members_own_step(one_torch_thread):
    from nl2policy.language.models.network import StackedDecoder, Translator

    torch.manual_seed(0)
    cfg = dataclasses.replace(MODELS["smoke"], hidden=24, embed=12)
    nets = [Translator(cfg, 30, 10).eval() for _ in range(3)]
    B, N, h, mem = 4, 7, 24, 48
    words, mask = torch.randn(3, B, N, mem), torch.rand(B, N) > 0.3
    mask[:, 0] = True
    h_prev, h_parent = torch.randn(3, B, h), torch.randn(3, B, h)
    ctx_prev = torch.randn(3, B, mem)
    prev_tok, parent_tok, branch = torch.tensor([10, 2, 3, 4]), torch.tensor([10, 10, 1, 2]), torch.tensor([0, 1, 2, 1])
    with torch.inference_mode():
        got = StackedDecoder(nets).step(words, mask, h_prev, ctx_prev, prev_tok, h_parent, parent_tok, branch)
        for e, net in enumerate(nets):
            want = net.step({"words": words[e], "mask": mask}, h_prev[e], ctx_prev[e], prev_tok, h_parent[e], parent_tok,
                            branch)
            for g, w in zip(got, want, strict=True):
                assert torch.allclose(g[e], w, atol=1e-5)


def test_stacked_encoder_equals_each_members_own_encoder(one_torch_thread):
    """On a padded batch (texts of 7, 3, 1 and 5 words): the stacked BiGRU reads each text from
    its own last word backwards and leaves zeros after it, as the packed nn.GRU does."""
    from nl2policy.language.models.network import Batch, StackedEncoder, Translator

    torch.manual_seed(0)
    cfg = dataclasses.replace(MODELS["smoke"], hidden=24, embed=12)
    nets = [Translator(cfg, 30, 10).eval() for _ in range(3)]
    lengths = torch.tensor([7, 3, 1, 5])
    inside = torch.arange(7)[None] < lengths[:, None]
    words = torch.randint(1, 30, (4, 7)) * inside
    batch = Batch(words, lengths, None, torch.zeros(4, 1, 7, dtype=torch.long), lengths[:, None], torch.ones(4, dtype=torch.long))
    with torch.inference_mode():
        got = StackedEncoder(nets).encode(batch)
        for g, net in zip(got, nets, strict=True):
            want = net.encode(batch)
            assert g.keys() == want.keys()
            for k in want:
                assert torch.allclose(g[k], want[k], atol=1e-6), k
        assert bool((got[0]["words"][~inside] == 0).all()) and bool((got[0]["words"][inside] != 0).any())


@pytest.mark.parametrize("beam", [1, 3])
def test_stacked_and_member_by_member_decoding_give_the_same_translations(beam, one_torch_thread):
    specs = load_corpus("highway")
    cfg = dataclasses.replace(MODELS["smoke"], epochs=3, batch=16, ensemble=3)
    model = fit("highway", "ens", cfg, [(s.description, s.tree) for s in specs[:48]], seed=0)
    model.beam = beam
    texts = [s.description for s in specs[48:80]]
    stacked = model.predict(texts)
    model.stack_members = False
    looped = model.predict(texts)
    assert [t for t, _ in stacked] == [t for t, _ in looped]
    for (_, a), (_, b) in zip(stacked, looped):
        assert a.keys() == b.keys() and all(abs(a[k] - b[k]) < 1e-5 for k in a)


def _assert_teacher_forced(model, text: str, tree, probs: dict) -> float:
    """The node probabilities decoding reported for `tree` multiply to the probability teacher
    forcing gives that tree (a single network); returns that log-probability."""
    from nl2policy.language.train import _targets, gold_steps
    from nl2policy.language.translator import collate

    logp = sum(math.log(p) for p in probs.values())
    steps = gold_steps(tree, model.domain, model.tree_tokens)
    with torch.inference_mode():
        nll = model.net.loss(collate([model.encode(text)]), *_targets([steps], len(model.tree_tokens)))
    assert -float(nll) * len(steps[0]) == pytest.approx(logp, abs=1e-4)
    return logp


def test_beam_search_reports_the_networks_own_probabilities_and_mostly_beats_greedy(one_torch_thread):
    """The beam's hypotheses are reordered every step; if a state were carried to the wrong
    hypothesis, the node probabilities it reports would not be the network's probabilities of
    that tree, which teacher forcing computes independently."""
    specs = load_corpus("highway")
    cfg = dataclasses.replace(MODELS["smoke"], epochs=3, batch=16)
    model = fit("highway", "one", cfg, [(s.description, s.tree) for s in specs[:48]], seed=0)
    texts = [s.description for s in specs[48:72]]
    greedy = model.predict(texts)
    model.beam = 4
    beamed = model.predict(texts)
    gains = []
    for text, (tree, probs), (_, greedy_probs) in zip(texts, beamed, greedy):
        logp = _assert_teacher_forced(model, text, tree, probs)
        gains.append(logp - sum(math.log(p) for p in greedy_probs.values()))
    # beam search may end below greedy on a text (greedy's path can be pruned), but not usually
    assert sum(gains) > 0 and sum(g > -1e-6 for g in gains) >= 0.75 * len(gains)


def test_findings_steer_the_beam_and_it_reports_the_networks_own_probabilities(one_torch_thread):
    """Findings that say every question is asked grow the beam's trees, and the node
    probabilities reported stay the networks' teacher-forced ones: a decoder state carried to
    the wrong hypothesis when the beam reorders would report others (the smoke model's own trees
    are single actions, where nothing is reordered). With no findings weight, decoding is as before."""
    from nl2policy.domains import get_domain
    from nl2policy.language.findings import Findings

    specs = load_corpus("highway")
    vocab = get_domain("highway").vocab
    cfg = dataclasses.replace(MODELS["smoke"], epochs=3, batch=16, beam=3)
    model = fit("highway", "one", cfg, [(s.description, s.tree) for s in specs[:48]], seed=0)
    texts = [s.description for s in specs[48:64]]
    size = lambda decoded: [len(to_tokens(t)) for t, _ in decoded]
    plain = model.predict(texts)
    labels = list(vocab.question_ids) + list(vocab.action_ids)
    every = Findings({q: 0.99 for q in vocab.question_ids}, {a: 0.5 for a in vocab.action_ids},
                     {l: 1 / len(labels) for l in labels})

    class Fixed:
        def read(self, batch):
            return [every for _ in batch]

    model.findings, model.findings_cost = Fixed(), 1.0
    steered = model.predict(texts)
    assert sum(size(steered)) > sum(size(plain))
    for text, (tree, probs) in zip(texts, steered):
        _assert_teacher_forced(model, text, tree, probs)
    # findings read once by the caller (translate: for decoding and its warnings) decode the same
    assert model.predict(texts, found=model.read_findings(texts)) == steered
    model.findings_cost = 0.0
    assert model.predict(texts) == plain


def test_members_can_train_on_their_own_draws_of_pairs(one_torch_thread):
    """With a function of the member index, each member reads its own pairs (and is still
    reproducible); the word vocabulary comes from the real texts only."""
    from nl2policy.language.dataset import member_pairs

    specs = load_corpus("taxi")[:30]
    cfg = dataclasses.replace(MODELS["smoke"], epochs=1, ensemble=2, synthetic=20, member_draws=True)
    draws = member_pairs("taxi", specs, range(30), cfg, seed=0)
    first, second = draws(0), draws(1)
    assert first[:30] == second[:30]  # the real descriptions are shared
    assert {t for t, _ in first[30:]}.isdisjoint({t for t, _ in second[30:]})  # augmented and synthetic differ
    asked = []
    model = fit("taxi", "d", cfg, lambda m: asked.append(m) or draws(m), seed=0,
                vocab_texts=[s.description for s in specs])
    assert asked == [0, 1] and len(model.nets) == 2
    again = fit("taxi", "d", cfg, draws, seed=0, vocab_texts=[s.description for s in specs])
    for n1, n2 in zip(model.nets, again.nets):
        for p1, p2 in zip(n1.parameters(), n2.parameters()):
            assert torch.equal(p1, p2)
    assert member_pairs("taxi", specs, range(30), dataclasses.replace(cfg, member_draws=False)) == first


def test_decoding_with_the_first_members_equals_training_only_those(one_torch_thread):
    """Members train independently (seed + m, draw + m), so decoding a 4-member model with its
    first 3 networks is the 3-member model trained alone: the record the experiment keeps for an
    ensemble larger than the default's."""
    specs = load_corpus("highway")
    cfg = dataclasses.replace(MODELS["smoke"], epochs=2, batch=16, ensemble=4, member_draws=True)
    draws = dataset.member_pairs("highway", specs, range(48), cfg)
    four = fit("highway", "ens", cfg, draws, seed=0)
    three = fit("highway", "ens", dataclasses.replace(cfg, ensemble=3), draws, seed=0)
    texts = [s.description for s in specs[48:72]]
    all_four = four.predict(texts)
    four.ensemble = 3
    first_three, alone = four.predict(texts), three.predict(texts)
    assert [t for t, _ in first_three] == [t for t, _ in alone]
    assert all(a == b for (_, a), (_, b) in zip(first_three, alone))  # same networks: same probabilities
    assert any(a != b for (_, a), (_, b) in zip(all_four, first_three))  # the fourth member did count


def test_a_list_of_synthetic_counts_gives_members_their_own_count_in_turn():
    from nl2policy.language.dataset import member_pairs
    from nl2policy.language.models.config import ModelConfig

    specs = load_corpus("taxi")[:30]
    cfg = dataclasses.replace(MODELS["smoke"], ensemble=3, synthetic=[7, 2], member_draws=True)
    assert cfg.synthetic == (7, 2) and hash(cfg)  # a list from a recipe file becomes a tuple: the config stays hashable
    draws = member_pairs("taxi", specs, range(30), cfg, seed=0)
    real_and_augmented = len(member_pairs("taxi", specs, range(30), dataclasses.replace(cfg, synthetic=0), seed=0)(0))
    # each synthetic draw: its random trees plus one generated description of each of the 30 training trees
    assert [len(draws(m)) - real_and_augmented - 30 for m in range(3)] == [7, 2, 7]
    one_count = dataclasses.replace(cfg, synthetic=7)
    assert member_pairs("taxi", specs, range(30), one_count, seed=0)(2) == draws(2)  # same seed, same count: same draw
    with pytest.raises(ValueError, match="member_draws"):
        dataclasses.replace(cfg, member_draws=False)
    with pytest.raises(ValueError, match="whole numbers"):
        ModelConfig("flat", "tree", False, [3, -1], member_draws=True)


def test_length_norm_ranks_the_beam_by_log_probability_per_node(one_torch_thread):
    """With length_norm the beam's finished trees come back ordered by score / nodes, the score
    itself staying the sum of node log-probabilities; at 0 the order is by the sum. Ranking per
    node lets larger trees through where the sum would favour the smaller."""
    from nl2policy.language.decoding import search
    from nl2policy.language.translator import collate

    specs = load_corpus("highway")
    cfg = dataclasses.replace(MODELS["smoke"], epochs=3, batch=16, beam=4)
    model = fit("highway", "one", cfg, [(s.description, s.tree) for s in specs[:48]], seed=0)
    texts = [s.description for s in specs[48:64]]
    batch = collate([model.encode(t) for t in texts])
    size = lambda decoded: [len(to_tokens(t)) for t, _ in decoded]
    plain = model.predict(texts)
    for norm in (0.0, 1.0):
        model.length_norm = norm
        with torch.inference_mode():
            found = search(model, batch, texts)
        assert len({len(to_tokens(tree)) for hyps in found for tree, _, _ in hyps}) > 2  # trees of many sizes to rank
        for text, hyps in zip(texts, found):
            ranks = [score / len(to_tokens(tree)) ** norm for tree, _, score in hyps]
            assert ranks == sorted(ranks, reverse=True)
            for tree, probs, score in hyps:
                assert score == pytest.approx(sum(math.log(p) for p in probs.values()), abs=1e-4)
    assert sum(size(model.predict(texts))) > sum(size(plain))
    model.length_norm = 0.0
    assert model.predict(texts) == plain
