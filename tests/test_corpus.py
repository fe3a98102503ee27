"""Corpus access: the shipped copy, the override, and splits that can hold writers out."""

import shutil

import pytest

from nl2policy.data import PACKAGE_DATA, corpus_dir
from nl2policy.language.corpus import kfold, load_corpus, writers


def test_shipped_copy_matches_shared_corpus_when_present():
    shared = PACKAGE_DATA.parents[2].parent / "shared" / "corpus"
    if not shared.is_dir():
        pytest.skip("no ../shared/corpus beside this checkout (a clone elsewhere)")
    for name in ("vocabulary.json", "taxi.jsonl", "highway.jsonl", "BRIEFING.md", "README.md",
                 "round2/README.md", "round2/taxi.jsonl", "round2/highway.jsonl"):
        assert (shared / name).read_bytes() == (PACKAGE_DATA / "corpus" / name).read_bytes(), f"run `make corpus`: {name}"


def test_load_with_writers():
    for domain in ("taxi", "highway"):
        specs = load_corpus(domain)
        assert len(specs) == 200
        assert len(writers(specs)) == 8
        assert all(s.domain == domain and s.description for s in specs)


def test_second_round_ships_beside_the_first_with_new_trees_and_writers():
    for domain in ("taxi", "highway"):
        first, second = load_corpus(domain), load_corpus(domain, rounds=(2,))
        assert len(second) == 120 and len(load_corpus(domain, rounds=(1, 2))) == 320
        assert set(writers(second)) == {"voice", "teen", "engineer", "memo"}
        assert not set(writers(first)) & set(writers(second))
        assert not {s.tree for s in first} & {s.tree for s in second}  # round 2's trees are all new
    with pytest.raises(ValueError, match="no collection round 3"):
        load_corpus("taxi", rounds=(3,))


def test_env_var_points_elsewhere(tmp_path, monkeypatch):
    for name in ("vocabulary.json", "taxi.jsonl"):
        shutil.copy(PACKAGE_DATA / "corpus" / name, tmp_path / name)
    lines = (tmp_path / "taxi.jsonl").read_text().splitlines()[:7]
    (tmp_path / "taxi.jsonl").write_text("\n".join(lines) + "\n")
    monkeypatch.setenv("NL2POLICY_CORPUS", str(tmp_path))
    assert corpus_dir() == tmp_path
    assert len(load_corpus("taxi")) == 7
    monkeypatch.setenv("NL2POLICY_CORPUS", str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError, match="NL2POLICY_CORPUS"):
        corpus_dir()


def test_bad_corpus_line_names_file_and_line(tmp_path, monkeypatch):
    shutil.copy(PACKAGE_DATA / "corpus" / "vocabulary.json", tmp_path)
    (tmp_path / "taxi.jsonl").write_text('{"id": "x", "domain": "taxi", "writer": "w", "tree": {"do": "fly"}, "description": "d"}\n')
    monkeypatch.setenv("NL2POLICY_CORPUS", str(tmp_path))
    with pytest.raises(ValueError, match=r"taxi.jsonl:1: .*unknown action 'fly'"):
        load_corpus("taxi")


def test_kfold_partitions_items():
    specs = load_corpus("taxi")
    seen = []
    for train, test in kfold(specs, k=5, seed=3):
        assert not set(train) & set(test)
        assert len(train) + len(test) == len(specs)
        seen += test
    assert sorted(seen) == list(range(len(specs)))
    assert [t for _, t in kfold(specs, 5, seed=3)] == [t for _, t in kfold(specs, 5, seed=3)]
    assert [t for _, t in kfold(specs, 5, seed=3)] != [t for _, t in kfold(specs, 5, seed=4)]


def test_kfold_by_writer_holds_whole_writers_out():
    specs = load_corpus("highway")
    folds = list(kfold(specs, k=4, seed=0, by_writer=True))
    held = []
    for train, test in folds:
        test_writers = {specs[i].writer for i in test}
        assert test_writers.isdisjoint({specs[i].writer for i in train})
        assert len(test_writers) == 2
        held += sorted(test_writers)
    assert sorted(held) == writers(specs)
    with pytest.raises(ValueError, match="only 8 writers"):
        list(kfold(specs, k=9, by_writer=True))


def test_leave_trees_out_folds_hold_whole_policies_out():
    from nl2policy.language.corpus import policy_key

    specs = load_corpus("taxi", rounds=(1, 2))
    folds = list(kfold(specs, 5, seed=1, by_tree=True))
    assert sorted(i for _, test in folds for i in test) == list(range(len(specs)))
    sizes = [len(test) for _, test in folds]
    assert max(sizes) - min(sizes) <= max(sizes) // 4  # near equal, although policies recur unevenly
    for train, test in folds:
        seen = {policy_key("taxi", specs[i].tree) for i in train}
        assert not seen & {policy_key("taxi", specs[i].tree) for i in test}
    assert [t for _, t in kfold(specs, 5, seed=2, by_tree=True)] != [t for _, t in folds]  # repeats differ
    with pytest.raises(ValueError):
        next(kfold(specs, 5, by_tree=True, by_writer=True))


def test_leave_trees_out_protocol_plans_five_folds_a_repeat_on_both_rounds():
    from experiments.translation.__main__ import parse_plan
    from experiments.translation.evaluate import PROTOCOL_ROUNDS, plan_folds

    specs = load_corpus("highway", rounds=PROTOCOL_ROUNDS["trees"])
    folds = plan_folds(specs, "trees", 2)
    assert [key for key, _, _ in folds][:6] == [f"trees-r0-f{f}" for f in range(5)] + ["trees-r1-f0"]
    assert len(folds) == 10 and len(specs) == 320
    assert parse_plan("single:trees3", ["taxi"], "single") == [("taxi", "seq2tree-minilm-synth", "trees", 3)]


@pytest.mark.parametrize("protocol", ["cv", "writers"])
def test_both_rounds_protocols_test_round_one_folds_and_add_round_two_to_every_training_fold(protocol):
    from experiments.translation.__main__ import parse_plan
    from experiments.translation.evaluate import PROTOCOL_ROUNDS, fold_count, plan_folds

    alone = plan_folds(load_corpus("taxi"), protocol, 2)
    specs = load_corpus("taxi", rounds=PROTOCOL_ROUNDS[protocol + "both"])
    both = plan_folds(specs, protocol + "both", 2)
    round2 = {i for i, s in enumerate(specs) if s.round == 2}
    assert len(both) == len(alone) == fold_count(protocol + "both", 2) and round2
    for (key, train, test), (own_key, own_train, own_test) in zip(both, alone):
        assert key == protocol + "both" + own_key[len(protocol):]
        assert test == own_test and set(train) == set(own_train) | round2  # round 1 comes first in both
    repeats = 2 if protocol == "cv" else 1
    written = f"single:{protocol}both" + ("2" if protocol == "cv" else "")
    assert parse_plan(written, ["taxi"], "single") == [("taxi", "seq2tree-minilm-synth", protocol + "both", repeats)]


def test_new_writer_folds_hold_out_each_round_two_writer_and_every_policy_they_describe():
    from nl2policy.language.corpus import new_writer_folds, policy_key

    specs = load_corpus("taxi", rounds=(1, 2))
    folds = list(new_writer_folds(specs))
    round2 = {s.writer for s in specs if s.round == 2}
    assert len(folds) == len(round2) == 4
    for train, test in folds:
        (writer,) = {specs[i].writer for i in test}
        assert writer in round2 and all(specs[i].writer != writer for i in train)
        held = {policy_key("taxi", specs[i].tree) for i in test}
        assert not held & {policy_key("taxi", specs[i].tree) for i in train}
        assert len(train) + len(test) >= len(specs) - 3  # only a few other specs share a held-out policy
