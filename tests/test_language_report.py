"""The translation experiment: its folds (what each records, never run twice, networks reused)
and its report, Table 1 (experiments/translation/summary.py)."""

import json

import pytest

from experiments.translation.summary import summarize


def _run(domain, model, fold, protocol, tree_acc, **extra):
    return {"n": 50, "valid": 50, "tree_acc": tree_acc, "token_acc": 0.9, "policy_acc": tree_acc, "train_pairs": 10,
            "seconds": 1.0, "domain": domain, "model": model, "fold": fold, "protocol": protocol, **extra}


def _summary(tmp_path, runs, **kw) -> str:
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    md = summarize([tmp_path / "runs.jsonl"], tmp_path / "table.md", "cmd", "budget", **kw)
    return md.read_text() + "\n" + (tmp_path / "table-details.md").read_text()


def test_table_one_sets_every_protocol_of_a_model_side_by_side_per_domain(tmp_path):
    from nl2policy.language.models.config import DEFAULT_MODEL

    runs = [_run("taxi", DEFAULT_MODEL, "cv-r0-f0", "cv", 0.5), _run("taxi", DEFAULT_MODEL, "cv-r0-f1", "cv", 0.7),
            _run("taxi", DEFAULT_MODEL, "trees-r0-f0", "trees", 0.25), _run("taxi", "seq2seq", "cv-r0-f0", "cv", 0.1),
            _run("highway", "seq2seq", "writers-f0", "writers", 0.3)]
    md = _summary(tmp_path, runs, planned=[("taxi", DEFAULT_MODEL, "trees", 5)])
    taxi = md.split("## taxi: exact tree accuracy")[1].split("##")[0]
    assert "| model | CV (round 1) | leave-trees-out (both rounds) |" in taxi  # only the protocols that ran
    assert "| seq2seq | 10.00 (0.00) [1] | - |" in taxi  # the paper's models first
    assert f"| {DEFAULT_MODEL} | 60.00 (10.00) [2] | 25.00 (0.00) [1] |" in taxi
    assert taxi.index("seq2seq") < taxi.index(DEFAULT_MODEL)
    highway = md.split("## highway: exact tree accuracy")[1].split("##")[0]
    assert "| seq2seq | 30.00 (0.00) [1] |" in highway and DEFAULT_MODEL not in highway
    assert "Every output is a valid tree: yes (250 translations)" in md
    assert f"taxi {DEFAULT_MODEL} trees: 4 of 5 folds to go" in md
    table = json.loads((tmp_path / "table.json").read_text())
    assert {(r["domain"], r["protocol"], r["model"]): r["tree_acc"]["mean"] for r in table["rows"]}[
        ("taxi", "cv", DEFAULT_MODEL)] == 60.0


def test_summary_counts_a_fold_recorded_twice_once_and_names_invalid_outputs(tmp_path):
    runs = [_run("taxi", "m", "cv-r0-f0", "cv", 0.5), _run("taxi", "m", "cv-r0-f0", "cv", 0.9),
            dict(_run("taxi", "m", "trees-r0-f0", "trees", 0.5), valid=49)]
    md = _summary(tmp_path, runs)
    assert "| m | 50.00 (0.00) [1] | 50.00 (0.00) [1] |" in md
    assert "Every output is a valid tree: NO: taxi m trees" in md


def test_summary_sets_the_defaults_cv_beside_the_paper_with_leave_writers_out(tmp_path):
    from nl2policy.language.models.config import DEFAULT_MODEL

    runs = [_run("taxi", DEFAULT_MODEL, f"cvboth-r{r}-f{f}", "cvboth", 0.9) for r in range(3) for f in range(5)]
    runs += [_run("taxi", DEFAULT_MODEL, "writersboth-f0", "writersboth", 0.7),
             _run("highway", DEFAULT_MODEL, "cv-r0-f0", "cv", 0.8)]
    part = _summary(tmp_path, runs).split("## The default against the paper")[1].split("\n## ")[0]
    assert "| taxi | CV, round 2 in training | 90.00 [15 folds] | 70.00 [1 folds] | 86.30 | yes |" in part
    assert "| highway | CV (round 1) | 80.00 [1 folds] | not run | 80.38 | no |" in part


def test_summary_keeps_the_defaults_missing_cv_in_view(tmp_path):
    """A default with leave-writers-out but no CV yet still has its row beside the paper: not run."""
    from nl2policy.language.models.config import DEFAULT_MODEL

    runs = [_run("taxi", DEFAULT_MODEL, "writers-f0", "writers", 0.75), _run("highway", "m", "cv-r0-f0", "cv", 0.8)]
    part = _summary(tmp_path, runs).split("## The default against the paper")[1].split("\n## ")[0]
    assert "| taxi | CV (round 1) | not run | 75.00 [1 folds] | 86.30 | - |" in part
    assert "| highway |" not in part  # the default has no highway fold at all


def test_table_one_keeps_to_exact_accuracy_and_links_the_details_file(tmp_path):
    _summary(tmp_path, [_run("taxi", "m", "cv-r0-f0", "cv", 0.5)])
    main, details = (tmp_path / "table.md").read_text(), (tmp_path / "table-details.md").read_text()
    assert "## taxi: exact tree accuracy" in main and "token accuracy" not in main.split("Token accuracy")[0]
    assert "[table-details.md](table-details.md)" in main
    assert "## taxi: token accuracy" in details and "exact tree accuracy" not in details


def test_reliability_table_bins_confidence_and_gives_the_accuracy_above_the_threshold(tmp_path):
    items = [["a", 0.95, True], ["b", 0.9, True], ["c", 0.85, False], ["d", 0.55, True], ["e", 0.3, False],
             ["f", 0.1, True], ["g", 0.05, False]]
    runs = [_run("taxi", "m", "trees-r0-f0", "trees", 0.5, confidence=items[:4]),
            _run("taxi", "m", "trees-r0-f1", "trees", 0.5, confidence=items[4:])]
    part = _summary(tmp_path, runs).split("## Confidence")[1]
    # 0-0.2: 1 of 2 right; 0.2-0.4: 0 of 1; 0.4-0.6: 1 of 1; 0.8-1: 2 of 3; at >= 0.5: 3 of 4; 3 of 7 flagged
    assert "| taxi | m | trees | 50 (2) | 0 (1) | 100 (1) | - (0) | 67 (3) | 75.0 | 42.9% |" in part


def test_summary_sets_each_decoding_choice_beside_the_same_folds_without_it(tmp_path):
    runs = [_run("taxi", "m", "cv-r0-f0", "cv", 0.75, greedy_tree_acc=0.5, no_findings_tree_acc=0.75),
            _run("taxi", "m", "cv-r0-f1", "cv", 0.5, greedy_tree_acc=0.75, no_findings_tree_acc=0.25),
            _run("taxi", "g", "cv-r0-f0", "cv", 0.5)]  # decoded greedily only: not in the table
    effects = _summary(tmp_path, runs).split("## Decoding choices")[1]
    assert "| taxi | m | cv | 2 | greedy (beam of 1) | 62.50 | 62.50 | 1 / 1 |" in effects
    assert "| taxi | m | cv | 2 | no learned findings | 62.50 | 50.00 | 1 / 0 |" in effects
    assert "| taxi | g |" not in effects


def test_the_summary_command_reads_several_runs_files_and_refuses_a_missing_one(tmp_path, monkeypatch, capsys):
    import sys

    from experiments.translation import summary

    for name, model in (("a", "m"), ("b", "n")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "runs.jsonl").write_text(json.dumps(_run("taxi", model, "cv-r0-f0", "cv", 0.5)) + "\n")
    out = tmp_path / "t" / "table1.md"
    monkeypatch.setattr(sys, "argv", ["summary", "--runs", str(tmp_path / "a" / "runs.jsonl"),
                                      "--runs", str(tmp_path / "b" / "runs.jsonl"), "--out", str(out)])
    summary.main()
    assert "| m | 50.00 (0.00) [1] |" in out.read_text() and "| n | 50.00 (0.00) [1] |" in out.read_text()
    monkeypatch.setattr(sys, "argv", sys.argv[:-2] + ["--model", "n=newer", "--out", str(out)])  # one model, renamed
    summary.main()
    assert "| newer | 50.00 (0.00) [1] |" in out.read_text() and "| m |" not in out.read_text()
    monkeypatch.setattr(sys, "argv", ["summary", "--runs", str(tmp_path / "none.jsonl"), "--out", str(out)])
    with pytest.raises(SystemExit, match="no such runs file"):
        summary.main()


def test_experiment_never_runs_a_fold_twice(tmp_path, monkeypatch):
    from experiments.translation import evaluate

    calls, workers, held = [], set(), set()

    def fake_fold(domain, specs, train_idx, test_idx, name, seed, cache, n_workers, keep=None, reuse=None,
                  hold_test_trees=False):
        calls.append((domain, name, tuple(test_idx)))
        workers.add(n_workers)
        held.add(hold_test_trees)
        return {"n": len(test_idx), "valid": len(test_idx), "tree_acc": 0.5, "token_acc": 0.5, "policy_acc": 0.5,
                "train_pairs": len(train_idx), "seconds": 0.0}

    monkeypatch.setattr(evaluate, "run_fold", fake_fold)
    plan = [("taxi", "m", "cv", 1), ("taxi", "m", "cv", 2)]  # cv2 holds cv1's folds: only 5 new ones
    evaluate.run_experiment(plan, tmp_path, workers=2)
    assert len(calls) == 10 == len(set(calls))
    assert workers == {2}  # each fold's training gets the worker processes asked for
    assert held == {False}  # CV holds out descriptions, not trees: random synthetic trees stay as drawn
    evaluate.run_experiment(plan, tmp_path)  # resuming a finished experiment runs nothing
    assert len(calls) == 10
    records = [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert len(records) == 10
    assert all(r["machine"] == evaluate.machine() != "" for r in records)  # where each fold trained
    assert all(r["workers"] == 2 for r in records)  # and how (its seconds depend on it)


def test_an_experiment_can_run_chosen_folds_first_and_the_rest_later(tmp_path, monkeypatch):
    from experiments.translation import evaluate

    keys, job = [], evaluate.Job
    monkeypatch.setattr(evaluate, "run_fold", lambda *a, **k: {"n": 1, "valid": 1, "tree_acc": 1.0, "token_acc": 1.0,
                                                                "policy_acc": 1.0, "train_pairs": 1, "seconds": 0.0})
    monkeypatch.setattr(evaluate, "Job", lambda name, fn, kwargs, cpus: (keys.append(kwargs["key"]),
                                                                         job(name, fn, kwargs, cpus))[1])
    plan = [("taxi", "m", "new", 1)]
    with pytest.raises(evaluate.UnknownFold, match="new-f9"):
        evaluate.run_experiment(plan, tmp_path, only_folds=["new-f1", "new-f9"])
    assert not (tmp_path / "runs.jsonl").exists()  # refused before any fold ran
    evaluate.run_experiment(plan, tmp_path, only_folds=["new-f3", "new-f1"])
    assert keys[-2:] == ["new-f1", "new-f3"]  # in plan order, only those
    evaluate.run_experiment(plan, tmp_path)  # the rest, resumed
    assert keys[-2:] == ["new-f0", "new-f2"]


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


@pytest.mark.train
def test_fold_result_with_a_beam_and_findings_also_records_decoding_without_them(monkeypatch, one_torch_thread):
    import dataclasses

    from experiments.translation import evaluate
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.models.config import MODELS
    from nl2policy.language.models.pretrained import MiniLMCache

    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["smoke"], epochs=2, beam=3, findings_cost=1.0))
    specs = load_corpus("taxi")[:40]
    cache = MiniLMCache()
    r = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, cache)
    assert 0 <= r["greedy_tree_acc"] <= 1 and "first_3_members_tree_acc" not in r  # one network: no smaller ensemble
    assert [c[0] for c in r["confidence"]] == [s.id for s in specs[30:]]  # each translation's confidence, for the bins
    assert sum(ok for _, _, ok in r["confidence"]) == round(r["tree_acc"] * 10)
    # the same training without the findings (same seed, same networks) scores what the fold recorded
    monkeypatch.setitem(MODELS, "tiny", dataclasses.replace(MODELS["tiny"], findings_cost=0.0))
    without = evaluate.run_fold("taxi", specs, list(range(30)), list(range(30, 40)), "tiny", 0, cache)
    assert without["tree_acc"] == r["no_findings_tree_acc"] and "no_findings_tree_acc" not in without


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


def test_plan_names_models_protocols_and_optionally_one_domain():
    from experiments.translation.__main__ import parse_plan
    from nl2policy.language.models.config import DEFAULT_MODEL

    steps = parse_plan("best:writers,cv3;taxi/seq2seq:cv1", ["taxi", "highway"], DEFAULT_MODEL)
    assert steps == [("taxi", DEFAULT_MODEL, "writers", 1), ("highway", DEFAULT_MODEL, "writers", 1),
                     ("taxi", DEFAULT_MODEL, "cv", 3), ("highway", DEFAULT_MODEL, "cv", 3), ("taxi", "seq2seq", "cv", 1)]
    for bad in ("no-such-model:cv1", "seq2seq", "seq2seq:cvx", "seq2seq:folds", "highway/seq2seq:cv1"):
        with pytest.raises(ValueError, match="plan part"):
            parse_plan(bad, ["taxi"], DEFAULT_MODEL)


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
    import torch

    from experiments.clarify import load_networks  # the simulated user decodes kept networks as saved, or as another model

    kept = torch.load(tmp_path / "taxi-tiny-cv-r0-f0.pt", weights_only=False)
    assert load_networks(kept, MiniLMCache()).translator.cfg == MODELS["tiny"]
    assert load_networks(kept, MiniLMCache(), decode_as="tiny-first").translator.cfg.beam == 2
    with pytest.raises(ValueError, match="does not train"):
        load_networks(kept, MiniLMCache(), decode_as="tiny-longer")
    monkeypatch.delitem(MODELS, "tiny")  # a candidate's registration deleted after it lost: its file says what trained it
    assert evaluate.kept_networks(tmp_path, "taxi", "tiny-first", "cv-r0-f0", train, test)["name"] == "tiny"
    assert load_networks(kept, MiniLMCache()).translator.cfg.epochs == 2
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
    assert out.exit_code == 2 and "protocol 'cv2x' is not cvR, treesR, writers, new" in " ".join(out.output.split())
    out = runner.invoke(lab, ["--domain", "taxi", "--plan", "seq2seq:cv1", "--out",
                              str(tmp_path / "empty"), "--summarize-only"])
    assert out.exit_code == 2 and "no folds to summarise" in out.output
    assert not (tmp_path / "empty").exists()  # nothing written


def test_search_errors_score_the_gold_tree_exactly_as_the_beam_scores_its_own(one_torch_thread):
    """experiments.translation.search_errors: decoding held to a tree gives that tree the score the
    beam ranked it by, so "gold above the returned tree" means the search missed it."""
    from experiments.translation.search_errors import judge
    from nl2policy.language.translate import get_model
    from nl2policy.domains import get_domain
    from nl2policy.trees import from_tokens, to_tokens

    translator = get_model("taxi").translator
    text = "If there is a passenger, drive to the airport; otherwise wait."
    returned = translator.hypotheses(text)[0][0]
    same = judge(translator, text, returned)
    assert same["right"] and same["in_wide_beam"]
    assert same["gold_score"] == pytest.approx(same["pred_score"], abs=1e-6)
    assert to_tokens(returned) == ["has_passenger", "go_airport", "wait"]
    swapped = judge(translator, text, from_tokens(["has_passenger", "wait", "go_airport"], get_domain("taxi").vocab))
    assert not swapped["right"] and swapped["gold_score"] < swapped["pred_score"]


def test_search_errors_refuses_an_unwritable_report_before_reading_any_fold(tmp_path, capsys):
    from experiments.translation.search_errors import main

    (tmp_path / "a-file").write_text("kept\n")
    with pytest.raises(SystemExit) as exc:
        main(["--domain", "taxi", "--folds", str(tmp_path / "no-folds"), "--fold-model", "v7",
              "--out", str(tmp_path / "a-file" / "report.md")])
    assert exc.value.code == 2
    assert "is a file, not a folder" in capsys.readouterr().err  # said before "no fold networks"
    assert (tmp_path / "a-file").read_text() == "kept\n"


def test_fresh_pairs_refuses_a_missing_translator_file_in_one_line(tmp_path, capsys):
    from experiments.translation.fresh_pairs import main

    with pytest.raises(SystemExit) as exc:
        main(["--domain", "lunar", "--file", f"gone={tmp_path / 'none.pt'}"])
    assert exc.value.code == 2
    assert "no translator file at" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["--domain", "lunar", "--file", "no-path-given"])
    assert exc.value.code == 2
    assert "expected NAME=PATH" in capsys.readouterr().err
    (tmp_path / "damaged.pt").write_bytes(b"\x00not a translator")
    with pytest.raises(SystemExit) as exc:
        main(["--domain", "lunar", "--file", f"bad={tmp_path / 'damaged.pt'}"])
    assert exc.value.code == 2
    assert "cannot read a translator from" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["--domain", "mars", "--file", f"bad={tmp_path / 'damaged.pt'}"])
    assert exc.value.code == 2
    assert "mars" in capsys.readouterr().err  # the domain is named, before the file is read
    with pytest.raises(SystemExit) as exc:
        main(["--domain", "lunar", "--seed", "-1", "--file", f"bad={tmp_path / 'damaged.pt'}"])
    assert exc.value.code == 2
    assert "--seed" in capsys.readouterr().err


def test_fresh_pairs_reads_the_shipped_file_once_per_findings_weight(tmp_path):
    """Each row is the file's own reading of the same fresh pairs at that weight, counted as a
    direct predict counts it; without --findings-cost the file's own weight is used."""
    from experiments.translation.fresh_pairs import main
    from nl2policy.language.corpus import policy_key
    from nl2policy.language.synthetic import synthetic_pairs
    from nl2policy.language.translate import load_model, shipped_path

    out = tmp_path / "reading.md"
    main(["--domain", "lunar", "--pairs", "6", "--seed", "4242", "--file", f"shipped={shipped_path('lunar')}",
          "--findings-cost", "0", "--findings-cost", "1", "--out", str(out)])
    rows = [[cell.strip() for cell in line.split("|")[1:-1]] for line in out.read_text().splitlines()
            if line.startswith("| shipped |")]
    assert [row[4] for row in rows] == ["0", "1"]
    pairs = synthetic_pairs("lunar", 6, 4242)
    translator = load_model(shipped_path("lunar"), "lunar").translator
    for row, cost in zip(rows, (0.0, 1.0)):
        translator.findings_cost = cost
        decoded = [tree for tree, _ in translator.predict([text for text, _ in pairs])]
        assert int(row[5]) == sum(tree == gold for tree, (_, gold) in zip(decoded, pairs))
        assert int(row[6]) == sum(policy_key("lunar", tree) == policy_key("lunar", gold) for tree, (_, gold) in zip(decoded, pairs))
    assert rows[1][7] == "right"  # the shipped file reads the domain's example (test_domains checks it too)
    main(["--domain", "lunar", "--pairs", "2", "--file", f"shipped={shipped_path('lunar')}", "--out", str(out)])
    own = [line for line in out.read_text().splitlines() if line.startswith("| shipped |")]
    assert len(own) == 1 and f"| {translator.cfg.findings_cost:g} (its own) |" in own[0]


def test_leave_style_out_refuses_to_resume_into_folds_of_other_settings(tmp_path, capsys):
    """A kept fold of another translator, or one that did not record its recipe, is not rewritten
    under today's settings: the command stops before training and the file is left as it was."""
    import json

    from experiments.translation.leave_style_out import main
    from nl2policy.language.models.config import DEFAULT_MODEL

    folder = tmp_path / "lunar"
    folder.mkdir()
    runs = folder / "runs.json"
    for row in ({"fold": "prose", "model": "v3", "seed": 0, "test_pairs": 240},  # another translator
                {"fold": "prose", "model": DEFAULT_MODEL, "seed": 0, "test_pairs": 240}):  # settings not recorded
        runs.write_text(json.dumps([row]))
        with pytest.raises(SystemExit) as exc:
            main(domain="lunar", synthetic=600, test_pairs=240, seed=0, out=tmp_path)
        assert exc.value.code == 2
        assert "prose" in capsys.readouterr().err
        assert json.loads(runs.read_text()) == [row]


def test_leave_style_out_resumes_only_the_same_recipe_seed_and_test_size():
    import dataclasses
    import json

    from experiments.translation.leave_style_out import resumable
    from nl2policy.language.models.config import DEFAULT_MODEL
    from nl2policy.language.shipping import shipped_config

    recipe = json.loads(json.dumps(dataclasses.replace(shipped_config("lunar"), synthetic=600).to_dict()))
    row = {"fold": "rule lists", "model": DEFAULT_MODEL, "recipe": recipe, "seed": 0, "test_pairs": 240}
    assert resumable(row, recipe, 0, 240)
    assert resumable(row, recipe, 0, 241)  # three held-out styles: 241 asks the same 80 pairs a style
    assert not resumable(row, recipe, 1, 240)
    assert not resumable(row, recipe, 0, 120)
    assert not resumable(row, {**recipe, "epochs": recipe["epochs"] + 1}, 0, 240)
    assert not resumable({**row, "model": "v3"}, recipe, 0, 240)
