"""The translation experiment's tables: means over folds, held-out writer names, what was not run."""

import dataclasses
import json

import pytest

from experiments.translation.evaluate import held_out_writers
from experiments.translation.reproduction import machine_kinds
from experiments.translation.summary import summarize


@pytest.fixture
def history_models(monkeypatch):
    """The default's past decodings (deleted from the config with the variants that lost), as the
    recorded folds name them: the summary and its reproduction checks read such records."""
    from nl2policy.language.models.config import MODELS, X4_MENTIONS

    base = "seq2tree-minilm-synth-x4-mentions"
    chain = {base + "-questions": dataclasses.replace(X4_MENTIONS, question_cost=1.0),
             base + "-questions-ext": dataclasses.replace(X4_MENTIONS, question_cost=2.0, question_forms="extended"),
             base + "-questions-ext-rules": dataclasses.replace(X4_MENTIONS, question_cost=2.0, question_forms="extended",
                                                                rule_cost=100.0),
             base + "-questions-ext-rules-ext": dataclasses.replace(X4_MENTIONS, question_cost=2.0, question_forms="extended",
                                                                    rule_cost=100.0, rule_forms="extended"),
             "seq2tree-minilm-synth-x6-mentions": dataclasses.replace(X4_MENTIONS, ensemble=6)}
    for name, cfg in chain.items():
        monkeypatch.setitem(MODELS, name, cfg)
    return chain


def _run(domain, model, fold, protocol, tree_acc):
    return {"n": 50, "valid": 50, "tree_acc": tree_acc, "token_acc": 0.9, "policy_acc": tree_acc, "train_pairs": 10,
            "seconds": 1.0, "domain": domain, "model": model, "fold": fold, "protocol": protocol}


def test_held_out_writer_pairs_partition_the_writers():
    pairs = held_out_writers("taxi")
    assert sorted(pairs) == [f"writers-f{f}" for f in range(4)]
    writers = [w for names in pairs.values() for w in names.split(" + ")]
    assert len(writers) == len(set(writers)) == 8


def test_summary_reports_mean_std_per_writer_pair_and_unfinished_rows(tmp_path):
    runs = [_run("taxi", "m", "cv-r0-f0", "cv", 0.5), _run("taxi", "m", "cv-r0-f1", "cv", 0.7),
            _run("taxi", "m", "writers-f0", "writers", 0.25), _run("taxi", "m", "writers-f2", "writers", 0.75)]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget", planned=[("taxi", "m", "cv", 5), ("taxi", "m", "writers", 4)]).read_text()
    assert "| taxi | m | cv | 2 | 60.00 (10.00) |" in md
    assert "| taxi | m | writers | 2 | 50.00 (25.00) |" in md
    pairs = held_out_writers("taxi")
    assert f"| taxi | {' | '.join(pairs[f'writers-f{f}'] for f in range(4))} |" in md
    assert "| m | 25 | not run | 75 | not run |" in md
    assert "taxi m cv: 3 of 5 folds" in md and "taxi m writers: 2 of 4 folds" in md
    table = json.loads((tmp_path / "translation.json").read_text())
    assert {r["protocol"]: r["tree_acc"]["mean"] for r in table["rows"]} == {"cv": 60.0, "writers": 50.0}
    assert (tmp_path / "translation.png").stat().st_size > 0


def test_experiment_never_runs_a_fold_twice(tmp_path, monkeypatch):
    from experiments.translation import evaluate

    calls, workers = [], set()

    def fake_fold(domain, specs, train_idx, test_idx, name, seed, cache, n_workers, keep=None, reuse=None):
        calls.append((domain, name, tuple(test_idx)))
        workers.add(n_workers)
        return {"n": len(test_idx), "valid": len(test_idx), "tree_acc": 0.5, "token_acc": 0.5, "policy_acc": 0.5,
                "train_pairs": len(train_idx), "seconds": 0.0}

    monkeypatch.setattr(evaluate, "run_fold", fake_fold)
    plan = [("taxi", "m", "cv", 1), ("taxi", "m", "cv", 2)]  # cv2 holds cv1's folds: only 5 new ones
    evaluate.run_experiment(plan, tmp_path, workers=2)
    assert len(calls) == 10 == len(set(calls))
    assert workers == {2}  # each fold's training gets the worker processes asked for
    evaluate.run_experiment(plan, tmp_path)  # resuming a finished experiment runs nothing
    assert len(calls) == 10
    records = [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert len(records) == 10
    assert all(r["machine"] == evaluate.machine() != "" for r in records)  # where each fold trained
    assert all(r["workers"] == 2 for r in records)  # and how (its seconds depend on it)


def test_summary_says_which_machine_ran_each_row(tmp_path):
    runs = [_run("taxi", "a", "cv-r0-f0", "cv", 0.5), _run("taxi", "a", "cv-r0-f1", "cv", 0.5),  # recorded no machine
            dict(_run("taxi", "b", "cv-r0-f0", "cv", 0.5), machine="cpu x"),
            dict(_run("taxi", "c", "cv-r0-f0", "cv", 0.5), machine="cpu x"), _run("taxi", "c", "cv-r0-f1", "cv", 0.5)]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert "A = not recorded; B = cpu x." in md
    assert "| taxi | a | cv | 2 | 50.00 (0.00) | 90.00 (0.00) | 50.00 (0.00) | yes | 10 | 1.0 | A |" in md
    assert "| taxi | b | cv | 1 | 50.00 (0.00) | 90.00 (0.00) | 50.00 (0.00) | yes | 10 | 1.0 | B |" in md
    assert "| taxi | c | cv | 2 | 50.00 (0.00) | 90.00 (0.00) | 50.00 (0.00) | yes | 10 | 1.0 | A 1, B 1 |" in md
    rows = {r["model"]: r["machines"] for r in json.loads((tmp_path / "translation.json").read_text())["rows"]}
    assert rows == {"a": {"not recorded": 2}, "b": {"cpu x": 1}, "c": {"not recorded": 1, "cpu x": 1}}


def test_summary_sets_the_best_fully_cross_validated_model_beside_the_paper(tmp_path):
    runs = [_run("taxi", "a", f"cv-r{r}-f{f}", "cv", 0.9) for r in range(3) for f in range(5)]
    runs += [_run("taxi", "b", f"cv-r{r}-f{f}", "cv", 0.8) for r in range(3) for f in range(5)]
    runs += [_run("taxi", "c", "cv-r0-f0", "cv", 1.0)]  # better, but one fold: not the paper's protocol
    runs += [_run("taxi", "a", "writers-f0", "writers", 0.7), _run("highway", "b", "cv-r0-f0", "cv", 0.9)]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert "| taxi | a | 90.00 (0.00) | 70.00 (1 of 4 folds) | 86.30 | yes |" in md
    assert "| highway |" not in md.split("## Best model against the paper")[1].split("##")[0]  # no full CV there


def test_summary_counts_a_fold_recorded_twice_once(tmp_path):
    runs = [_run("taxi", "m", "cv-r0-f0", "cv", 0.5), _run("taxi", "m", "cv-r0-f0", "cv", 0.9)]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    assert "| taxi | m | cv | 1 | 50.00 (0.00) |" in summarize(tmp_path, "cmd", "budget").read_text()


def test_summary_pools_confidence_calibration_over_folds(tmp_path):
    a = dict(_run("taxi", "m", "cv-r0-f0", "cv", 0.5), n=10, confident=6, confident_right=5, unsure_right=0)
    b = dict(_run("taxi", "m", "cv-r0-f1", "cv", 0.5), n=10, confident=4, confident_right=3, unsure_right=2)
    (tmp_path / "runs.jsonl").write_text(json.dumps(a) + "\n" + json.dumps(b) + "\n")
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert "| taxi | m | cv | 50.0 | 80.0 | 20.0 |" in md  # 10 of 20 confident, 8/10 right; 2/10 unsure right


def test_unseen_trees_are_the_test_trees_no_training_description_has():
    from nl2policy.language.corpus import load_corpus
    from experiments.translation.evaluate import unseen_trees
    from nl2policy.trees import to_tokens

    specs = load_corpus("taxi")
    key = lambda i: tuple(to_tokens(specs[i].tree))
    repeated = next(i for i in range(len(specs)) if any(key(j) == key(i) for j in range(len(specs)) if j != i))
    twin = next(j for j in range(len(specs)) if j != repeated and key(j) == key(repeated))
    single = next(i for i in range(len(specs)) if all(key(j) != key(i) for j in range(len(specs)) if j != i))
    rest = [i for i in range(len(specs)) if i not in (repeated, twin, single)]
    assert unseen_trees(specs, rest + [twin], [repeated, single]) == [False, True]
    assert unseen_trees(specs, [i for i in rest if key(i) != key(repeated)], [repeated, twin]) == [True, True]


def test_summary_counts_unseen_test_trees_and_pools_accuracy_on_them(tmp_path):
    a = dict(_run("taxi", "m", "cv-r0-f0", "cv", 0.8), n=10, unseen=4, unseen_right=2)  # 8 right: 2 unseen, 6 seen
    b = dict(_run("taxi", "m", "cv-r0-f1", "cv", 0.5), n=10, unseen=2, unseen_right=0)  # 5 right, all seen
    c = _run("taxi", "old", "cv-r0-f0", "cv", 0.5)  # a fold from before the record: only in the data table
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in (a, b, c)))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert "| taxi | m | cv | 2 | 6 | 33.3 | 78.6 |" in md  # 2 of 6 unseen right; 11 of 14 seen
    assert "| taxi | old |" not in md.split("acc on unseen")[1]
    import re

    counts = re.search(r"\| taxi \| cv \| 600 \| (\d+) \| ([\d.]+) \|", md)  # the corpus's 3 x 200 CV tests alone
    assert counts and 0 < int(counts[1]) < 600 and float(counts[2]) == round(100 * int(counts[1]) / 600, 1)


def test_fold_result_counts_confident_and_unsure_translations(monkeypatch, one_torch_thread, tmp_path):
    import dataclasses

    import torch

    from experiments.translation import evaluate
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.models.config import MODELS
    from nl2policy.language.models.pretrained import MiniLMCache
    from nl2policy.trees import to_tokens

    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["smoke"], epochs=2))
    specs = load_corpus("taxi")[:40]
    kept = tmp_path / "nets" / "fold.pt"
    r = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, MiniLMCache(), keep=kept)
    saved = torch.load(kept, weights_only=False)  # the fold's networks, to decode again without retraining
    assert saved["test"] == list(range(30, 40)) and saved["train"] == list(range(30)) and len(saved["nets"]) == 1
    assert 0 <= r["confident"] <= r["n"] == 10
    assert r["confident_right"] + r["unsure_right"] == round(r["tree_acc"] * 10)
    assert r["confident_right"] <= r["confident"]
    assert r["unseen"] == sum(evaluate.unseen_trees(specs, list(range(30)), list(range(30, 40))))
    assert r["unseen_right"] <= min(r["unseen"], round(r["tree_acc"] * 10))
    assert len(r["errors"]) == 10 - round(r["tree_acc"] * 10)  # each wrong translation, to read back later
    ids = {s.id: s for s in specs[30:]}
    for sid, tokens in r["errors"]:
        assert " ".join(to_tokens(ids[sid].tree)) != tokens


def test_summary_sets_each_decoding_choice_beside_the_same_folds_without_it(tmp_path):
    a = dict(_run("taxi", "m", "cv-r0-f0", "cv", 0.75), greedy_tree_acc=0.5)
    b = dict(_run("taxi", "m", "cv-r0-f1", "cv", 0.5), greedy_tree_acc=0.75)
    c = dict(_run("taxi", "m", "cv-r0-f2", "cv", 0.5), greedy_tree_acc=0.25)
    plain = _run("taxi", "g", "cv-r0-f0", "cv", 0.5)  # decoded greedily only: not in the table
    # with a leaf cost: repeat 0 (where the cost was chosen) apart from the later repeats
    d = dict(_run("highway", "m", "cv-r0-f0", "cv", 0.75), no_leaf_cost_tree_acc=0.5)
    e = dict(_run("highway", "m", "cv-r1-f0", "cv", 0.5), no_leaf_cost_tree_acc=0.75)
    f = dict(_run("highway", "m", "cv-r2-f3", "cv", 1.0), no_leaf_cost_tree_acc=0.75)
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in (a, b, c, plain, d, e, f)))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    effects = md.split("## Decoding choices")[1]
    assert "| taxi | m | cv, repeat 0 | 3 | greedy (beam of 1) | 58.33 | 50.00 | 2 / 1 |" in effects
    assert "| highway | m | cv, repeat 0 | 1 | no early-leaf cost | 75.00 | 50.00 | 1 / 0 |" in effects
    assert "| highway | m | cv, repeats 1+ | 2 | no early-leaf cost | 75.00 | 75.00 | 1 / 1 |" in effects
    assert "| taxi | g |" not in effects and "| taxi | m | cv, repeat 0 | 3 | no early-leaf cost" not in effects


def test_fold_result_with_a_beam_and_decoding_costs_also_records_decoding_without_them(monkeypatch, one_torch_thread):
    import dataclasses

    from experiments.translation import evaluate
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.models.config import MODELS
    from nl2policy.language.models.pretrained import MiniLMCache
    from nl2policy.trees import to_tokens

    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["smoke"], epochs=2, beam=3, root_cost=100.0,
                                                            mention_cost=100.0))
    specs = load_corpus("taxi")[:40]
    r = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, MiniLMCache())
    assert 0 <= r["greedy_tree_acc"] <= 1 and "first_3_members_tree_acc" not in r  # one network: no smaller ensemble
    # the same training without one of the costs (same seed, same networks) scores what the fold
    # recorded as "without" it
    without = {}
    for cost in ("root_cost", "mention_cost"):
        monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["tiny"], **{cost: 0.0}))
        without[cost] = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, MiniLMCache())
        assert without[cost]["tree_acc"] == r[f"no_{cost}_tree_acc"] and f"no_{cost}_tree_acc" not in without[cost]
        monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["tiny"], **{cost: 100.0}))
    assert without["root_cost"]["token_acc"] != r["token_acc"]  # a prohibitive root cost (the stated first question) changed the trees


def test_summary_sets_each_variant_of_the_default_beside_it_on_the_folds_both_ran(tmp_path, monkeypatch):
    import dataclasses

    from nl2policy.language.models.config import DEFAULT_NETWORKS as base, MODELS

    monkeypatch.setitem(MODELS, base + "-x", dataclasses.replace(MODELS[base], ensemble=6, beam=1))
    monkeypatch.setitem(MODELS, "other", dataclasses.replace(MODELS[base], synthetic=0))  # no synthetic pairs: the ablation
    monkeypatch.setitem(MODELS, base + "-more", dataclasses.replace(MODELS[base], synthetic=2 * MODELS[base].synthetic))
    monkeypatch.setitem(MODELS, base + "-again", dataclasses.replace(MODELS[base], seed_offset=7))

    runs = [_run("taxi", base, f"cv-r{r}-f0", "cv", acc) for r, acc in ((0, 0.5), (1, 1.0), (2, 1.0))]
    runs += [_run("taxi", base + "-x", "cv-r0-f0", "cv", 0.75),  # the default's other repeats must not count
             _run("taxi", base + "-x", "writers-f0", "writers", 1.0),  # no default fold to set beside it
             _run("taxi", "other", "cv-r0-f0", "cv", 0.0),  # not a variant of the default
             _run("taxi", base + "-more", "cv-r1-f0", "cv", 0.25),  # more synthetic pairs: a variant
             _run("taxi", base + "-again", "cv-r2-f0", "cv", 0.75),  # other seeds only: a rerun
             _run("taxi", "seq2seq", "cv-r0-f0", "cv", 0.0)]  # nor is a baseline
    # a fold the default ran on one kind of CPU and the variant on another: two training runs, not a pair
    runs += [_run("taxi", base, "cv-r0-f1", "cv", 0.5), dict(_run("taxi", base + "-x", "cv-r0-f1", "cv", 0.0), machine="other cpu")]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    part = summarize(tmp_path, "cmd", "budget").read_text().split("## Variants")[1].split("\n## ")[0]
    assert f"| taxi | {base}-x | cv | 1 | 75.00 | 50.00 | 1 / 0 |" in part
    assert f"| taxi | {base}-more | cv | 1 | 25.00 | 100.00 | 0 / 1 |" in part
    assert f"| taxi | {base}-again | cv | 1 | 75.00 | 100.00 | 0 / 1 |" in part
    assert f"{base}-again: the default's own recipe trained again with other seeds" in part  # named as the yardstick
    assert f"{base}-more: the default's own" not in part and f"{base}-x: the default's own" not in part
    assert "writers" not in part and "| taxi | other |" not in part and "seq2seq" not in part


def test_fold_result_of_a_larger_ensemble_also_records_its_first_three_members(monkeypatch, one_torch_thread):
    import dataclasses

    from experiments.translation import evaluate
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.models.config import MODELS
    from nl2policy.language.models.pretrained import MiniLMCache

    specs = load_corpus("taxi")[:40]
    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["smoke"], epochs=1, ensemble=4, member_draws=True))
    r = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, MiniLMCache())
    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["tiny"], ensemble=3))
    three = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, MiniLMCache())
    assert r["first_3_members_tree_acc"] == three["tree_acc"] and "first_3_members_tree_acc" not in three


def test_machines_whose_folds_retrain_the_same_networks_count_as_one_kind(tmp_path, history_models):
    from nl2policy.language.models.config import DEFAULT_NETWORKS as base, MODELS

    six = next(name for name, cfg in MODELS.items() if cfg == dataclasses.replace(MODELS[base], ensemble=6))
    runs = []
    for f in range(5):  # the six-member model on an unrecorded machine, the default's own folds on "cpu x"
        runs += [dict(_run("taxi", six, f"cv-r0-f{f}", "cv", 0.75), first_4_members_tree_acc=0.5 + f / 50),
                 dict(_run("taxi", base, f"cv-r0-f{f}", "cv", 0.5 + f / 50), machine="cpu x")]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert "A with B 5 of 5" in md and "one kind of CPU in the paired tables (all of at least 5 agree): B = A." in md
    assert f"| taxi | {six} | cv | 5 | 75.00 | 54.00 | 5 / 0 |" in md.split("## Variants")[1]  # paired across A and B
    report = json.loads((tmp_path / "translation.json").read_text())
    assert report["reproduction"] == [{"machines": ["cpu x", "not recorded"], "agree": 5, "folds": 5}]

    # one fold that disagrees: two kinds, and the variants are no longer set beside the default
    runs[-1]["tree_acc"] = 0.0
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert "A with B 4 of 5" in md and "one kind of CPU" not in md and "## Variants" not in md


def test_decoding_choices_name_the_model_whose_config_the_smaller_decoding_is(tmp_path, monkeypatch, history_models):
    from nl2policy.language.models.config import DEFAULT_NETWORKS as base, MODELS

    six = next(name for name, cfg in MODELS.items() if cfg == dataclasses.replace(MODELS[base], ensemble=6))
    monkeypatch.setitem(MODELS, "wide-six", dataclasses.replace(MODELS[six], hidden=3 * MODELS[six].hidden))
    runs = [dict(_run("taxi", name, "cv-r0-f0", "cv", 0.75), first_4_members_tree_acc=0.5) for name in (six, "wide-six")]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert f"| taxi | {six} | cv, repeat 0 | 1 | its first 4 members (= {base}) | 75.00 | 50.00 | 1 / 0 |" in md
    # other networks than any model's: nothing named, and nothing counted as a reproduction check
    assert "| taxi | wide-six | cv, repeat 0 | 1 | its first 4 members | 75.00 | 50.00 | 1 / 0 |" in md
    assert json.loads((tmp_path / "translation.json").read_text())["reproduction"] == []


def test_too_few_agreeing_folds_do_not_make_one_kind():
    labels = {"x": "A", "y": "B", "z": "C"}
    assert machine_kinds({("x", "y"): (4, 4)}, labels) == {"x": "x", "y": "y", "z": "z"}
    assert machine_kinds({("x", "y"): (5, 5), ("y", "z"): (6, 6)}, labels) == {"x": "x", "y": "x", "z": "x"}
    assert machine_kinds({("x", "x"): (9, 9), ("x", "z"): (8, 9)}, labels) == {"x": "x", "y": "y", "z": "z"}


def test_plan_names_models_protocols_and_optionally_one_domain():
    from experiments.translation.__main__ import parse_plan
    from nl2policy.language.models.config import DEFAULT_MODEL

    steps = parse_plan("best:writers,cv3;taxi/seq2seq:cv1", ["taxi", "highway"], DEFAULT_MODEL)
    assert steps == [("taxi", DEFAULT_MODEL, "writers", 1), ("highway", DEFAULT_MODEL, "writers", 1),
                     ("taxi", DEFAULT_MODEL, "cv", 3), ("highway", DEFAULT_MODEL, "cv", 3), ("taxi", "seq2seq", "cv", 1)]
    for bad in ("no-such-model:cv1", "seq2seq", "seq2seq:cvx", "seq2seq:folds", "highway/seq2seq:cv1"):
        with pytest.raises(ValueError, match="plan part"):
            parse_plan(bad, ["taxi"], DEFAULT_MODEL)


def test_without_its_question_check_a_model_decodes_as_its_networks_plain_model(history_models):
    """Which patterns a question check uses changes nothing once the check is off, so the extended
    check's folds, decoded without it, are the default networks' folds (a reproduction check)."""
    from nl2policy.language.models.config import DEFAULT_NETWORKS
    from experiments.translation.reproduction import decoded_as

    ext = "seq2tree-minilm-synth-x4-mentions-questions-ext"
    assert decoded_as(ext, "no_question_cost_tree_acc") == [DEFAULT_NETWORKS]
    assert decoded_as(ext, "question_cost_1_tree_acc") == []  # the conditions-only model uses other patterns
    assert decoded_as("seq2tree-minilm-synth-x4-mentions-questions", "no_question_cost_tree_acc") == [DEFAULT_NETWORKS]
    # the default without its rule check is the extended question model, whose folds it reproduces
    assert decoded_as("seq2tree-minilm-synth-x4-mentions-questions-ext-rules", "no_rule_cost_tree_acc") == [ext]
    # which forms a rule check reads changes nothing once it is off; the default without its root cost
    rules_ext = "seq2tree-minilm-synth-x4-mentions-questions-ext-rules-ext"
    assert decoded_as(rules_ext, "no_rule_cost_tree_acc") == [ext]
    assert decoded_as(rules_ext + "-root", "no_root_cost_tree_acc") == [rules_ext]


def test_summary_marks_folds_that_decoded_another_models_networks_and_checks_no_reproduction_with_them(tmp_path, history_models):
    """A fold that decoded saved networks (--networks-from) retrained nothing: its seconds are
    decoding only, and it is no evidence that training reproduces."""
    from experiments.translation.reproduction import reproduction_checks

    ext = "seq2tree-minilm-synth-x4-mentions-questions-ext"
    runs = [dict(_run("taxi", ext, "cv-r0-f0", "cv", 0.5), machine="cpu x"),
            dict(_run("taxi", ext + "-rules", "cv-r0-f0", "cv", 0.75), machine="cpu x", no_rule_cost_tree_acc=0.5,
                 networks_from=ext)]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize(tmp_path, "cmd", "budget").read_text()
    assert f"| taxi | {ext}-rules | cv | 1 | 75.00 (0.00) | 90.00 (0.00) | 75.00 (0.00) | yes | 10 | 1.0 * | A |" in md
    assert f"| taxi | {ext} | cv | 1 | 50.00 (0.00) | 90.00 (0.00) | 50.00 (0.00) | yes | 10 | 1.0 | A |" in md
    assert "\\* decoded the networks another model trained" in md
    assert reproduction_checks(runs) == {}
    del runs[1]["networks_from"]  # had it trained them, it would check the other's fold
    assert reproduction_checks(runs) == {("cpu x", "cpu x"): (1, 1)}


def test_a_fold_can_decode_the_networks_another_model_trained_on_it(monkeypatch, one_torch_thread, tmp_path):
    """--keep-networks, then --networks-from: a model that differs only in decoding decodes the
    saved networks of the same fold, and scores what training them anew gives."""
    import dataclasses

    from experiments.translation import evaluate
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.models.config import MODELS
    from nl2policy.language.models.pretrained import MiniLMCache

    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["smoke"], epochs=2, ensemble=2))
    monkeypatch.setitem(MODELS, "tiny-first", dataclasses.replace(MODELS["tiny"], ensemble=1, beam=2))
    monkeypatch.setitem(MODELS, "tiny-longer", dataclasses.replace(MODELS["tiny"], epochs=3))
    specs = load_corpus("taxi")[:40]
    train, test = list(range(30)), list(range(30, 40))
    evaluate.run_fold("taxi", specs, train, test, "tiny", 0, MiniLMCache(), keep=tmp_path / "taxi-tiny-cv-r0-f0.pt")
    saved = evaluate.kept_networks(tmp_path, "taxi", "tiny-first", "cv-r0-f0", train, test)
    assert saved is not None and saved["name"] == "tiny"
    assert evaluate.kept_networks(tmp_path, "taxi", "tiny-longer", "cv-r0-f0", train, test) is None  # other training
    assert evaluate.kept_networks(tmp_path, "taxi", "tiny-first", "cv-r0-f0", train[1:], test) is None  # other fold
    reused = evaluate.run_fold("taxi", specs, train, test, "tiny-first", 0, MiniLMCache(), reuse=saved)
    trained = evaluate.run_fold("taxi", specs, train, test, "tiny-first", 0, MiniLMCache())
    for key in ("tree_acc", "token_acc", "errors", "greedy_tree_acc"):
        assert reused[key] == trained[key]


def test_translation_experiment_rejects_a_bad_plan_or_nothing_to_summarise(tmp_path):
    """The lab's command line (python -m experiments.translation): bad input is a one-line error."""
    import typer
    from typer.testing import CliRunner

    from experiments.translation.__main__ import translation_experiment

    lab, runner = typer.Typer(), CliRunner()
    lab.command()(translation_experiment)
    out = runner.invoke(lab, ["--domain", "taxi", "--plan", "seq2seq:cv2x", "--out", str(tmp_path)])
    assert out.exit_code == 2 and "protocol 'cv2x' is not cvR, treesR, writers or new" in " ".join(out.output.split())
    out = runner.invoke(lab, ["--domain", "taxi", "--plan", "seq2seq:cv1", "--out",
                              str(tmp_path / "empty"), "--summarize-only"])
    assert out.exit_code == 2 and "no folds to summarise" in out.output
    assert not (tmp_path / "empty").exists()  # nothing written
