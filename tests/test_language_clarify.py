"""Asking when unsure (issue 42): questions only about situations the domain allows, in its words;
every tree returned acts as every answer says (decoding is held to them, not a filter); bad
answers are refused with a clear message by the library, the API and the CLI, and nothing is
stored."""

import json
import random

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from nl2policy.app.server import create_app
from nl2policy.cli import app as cli
from nl2policy.domains import get_domain
from nl2policy.language.clarify import (Answer, BadAnswer, NoTreeFits, agrees, best_question, parse_answers,
                                        situation_text, situations)
from nl2policy.language.corpus import load_corpus
from nl2policy.language.translate import get_model, translate, translate_with
from nl2policy.trees.parse import validate

VAGUE = "Drive around and make money, but mind the traffic."


def test_situations_are_exactly_the_ones_the_domain_allows():
    for domain in ("taxi", "highway"):
        d = get_domain(domain)
        got = situations(domain)
        assert len(got) == len(d.possible_answer_sets) == len(set(got))
        assert all(d.is_possible(dict(s)) for s in got)
    assert len(situations("taxi")) == 24  # one of three places, times 2 x 2 x 2


def test_a_situation_is_told_in_the_domains_words_without_implied_facts():
    s = dict(at_airport=False, at_village=True, at_city=False, has_passenger=False, heavy_traffic=True, long_wait=False)
    text = situation_text("taxi", tuple(s.items()))
    assert text == ("The taxi is at the village, the taxi is empty, the traffic to the city is heavy and the wait "
                    "at the village is short. What should it do?")
    lane = next(x for x in situations("highway") if dict(x)["in_left_lane"])
    assert "left lane is not free" not in situation_text("highway", lane)  # the leftmost lane implies it


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_every_question_is_about_an_allowed_situation_and_every_tree_agrees_with_the_answers(domain):
    """Answer each question with a random action (not the tree's): the next tree must act so
    there, whatever the model thought before."""
    rng = random.Random(0)
    loaded = get_model(domain)
    d = get_domain(domain)
    allowed = set(situations(domain))
    asked_some = 0
    for spec in load_corpus(domain, rounds=(2,)):
        if asked_some >= 3:
            break
        answers = []
        result = translate_with(loaded, domain, spec.description, answers)
        while result.questions:
            q = result.questions[0]
            assert q.situation in allowed and q.text.endswith("What should it do?")
            assert [a for a, _ in q.choices] == d.vocab.action_ids
            other = rng.choice([a for a in d.vocab.action_ids if a != result.tree.act(dict(q.situation))])
            answers.append(Answer(q.situation, other))
            result = translate_with(loaded, domain, spec.description, answers)  # replays and checks the questions
            validate(result.tree, d.vocab)
            assert agrees(result.tree, answers)
            asked_some += 1
    assert asked_some >= 3


def test_an_answer_that_confirms_the_tree_leaves_it_as_it_is():
    """Answering each question with what the shown tree already does there never redraws it."""
    loaded = get_model("taxi")
    confirmed = 0
    for spec in load_corpus("taxi", rounds=(2,)):
        if confirmed >= 3:
            break
        result = translate_with(loaded, "taxi", spec.description)
        shown, answers = result.tree, []
        while result.questions:
            q = result.questions[0]
            answers.append(Answer(q.situation, shown.act(dict(q.situation))))
            result = translate_with(loaded, "taxi", spec.description, answers)
            assert result.tree == shown
            confirmed += 1
    assert confirmed >= 3


def test_the_question_asked_is_where_the_plausible_trees_disagree_most():
    """Three candidates: one tree (weight 0.5) and two that differ from it in different
    situations (0.3 in the city with a passenger, 0.2 at the airport): the city splits the
    weight 0.7 / 0.3 (1 - 0.49 - 0.09 = 0.42), the airport 0.8 / 0.2 (0.32), so the city is asked
    first, then the airport, then nothing once both are answered."""
    from math import log
    from nl2policy.trees.tokens import from_tokens
    vocab = get_domain("taxi").vocab
    shown = from_tokens("at_city go_airport go_city".split(), vocab)
    city = from_tokens("at_city has_passenger go_village go_airport go_city".split(), vocab)
    airport = from_tokens("at_airport wait at_city go_airport go_city".split(), vocab)
    hyps = [(shown, {}, log(0.5)), (city, {}, log(0.3)), (airport, {}, log(0.2))]
    first = dict(best_question("taxi", hyps, []))
    assert first["at_city"] and first["has_passenger"]
    done = [Answer(s, shown.act(dict(s))) for s in situations("taxi") if dict(s)["at_city"] and dict(s)["has_passenger"]]
    second = dict(best_question("taxi", hyps, done))
    assert second["at_airport"]
    done += [Answer(s, shown.act(dict(s))) for s in situations("taxi") if dict(s)["at_airport"]]
    assert best_question("taxi", hyps, done) is None


def test_a_confident_translation_asks_nothing():
    spec = load_corpus("taxi")[0]
    result = translate("taxi", spec.description)
    assert result.confidence >= 0.6 and result.questions == []


def test_answers_no_tree_can_follow_are_said_to_be_impossible():
    """Parity of four facts needs four questions on a path; a tree has at most three."""
    loaded = get_model("taxi")
    d = get_domain("taxi")
    answers = []
    for s in situations("taxi"):
        f = dict(s)
        odd = (f["has_passenger"] + f["heavy_traffic"] + f["long_wait"] + f["at_city"]) % 2
        answers.append(Answer(s, "wait" if odd else "go_city"))
    assert len(answers) == len(d.possible_answer_sets)
    with pytest.raises(NoTreeFits):
        translate_with(loaded, "taxi", VAGUE, answers, max_questions=len(answers), check_asked=False)


def _asked(domain="taxi", text=VAGUE):
    q = translate(domain, text).questions[0]
    return dict(q.situation)


@pytest.mark.parametrize("bad,needle", [
    (lambda s: [{"situation": s, "do": "fly"}], "unknown action"),
    (lambda s: [{"situation": {**s, "at_airport": True, "at_city": True}, "do": "wait"}], "never has this situation"),
    (lambda s: [{"situation": {k: v for k, v in s.items() if k != "long_wait"}, "do": "wait"}], "does not answer long_wait"),
    (lambda s: [{"situation": {**s, "at_mars": True}, "do": "wait"}], "unknown question"),
    (lambda s: [{"situation": s, "do": "wait"}, {"situation": s, "do": "go_city"}], "contradicts"),
    (lambda s: [{"situation": {**s, "long_wait": not s["long_wait"]}, "do": "wait"}], "not asked"),
    (lambda s: ["wait"], "expected"),
    (lambda s: [{"situation": {**s, "long_wait": "yes"}, "do": "wait"}], "true or false"),
])
def test_bad_answers_are_refused_everywhere_and_nothing_is_stored(tmp_path, bad, needle):
    answers = bad(_asked())
    with pytest.raises(BadAnswer, match=needle):
        translate("taxi", VAGUE, answers=answers)
    client = TestClient(create_app(tmp_path / "a.sqlite", tmp_path, results_dir=tmp_path, max_parallel_runs=0),
                        base_url="http://127.0.0.1")
    with client:
        r = client.post("/api/translate", json={"domain": "taxi", "description": VAGUE, "answers": answers})
        assert r.status_code == 422 and needle in r.json()["detail"]["message"] and r.json()["detail"]["where"] == "answers"
    import sqlite3

    with sqlite3.connect(tmp_path / "a.sqlite") as db:
        assert db.execute("SELECT COUNT(*) FROM specs").fetchone()[0] == 0
    result = CliRunner().invoke(cli, ["translate", "--domain", "taxi", *sum((["--answer", json.dumps(a)] for a in answers), []), VAGUE])
    assert result.exit_code == 2 and needle in result.stderr and "Traceback" not in result.output


def test_a_malformed_answer_on_the_command_line_is_one_line():
    result = CliRunner().invoke(cli, ["translate", "--domain", "taxi", "--answer", "{situation", VAGUE])
    assert result.exit_code == 2 and result.stderr.startswith("error: --answer 1 is not JSON")


def test_the_api_and_cli_return_questions_and_take_answers_back(tmp_path):
    client = TestClient(create_app(tmp_path / "a.sqlite", tmp_path, results_dir=tmp_path, max_parallel_runs=0),
                        base_url="http://127.0.0.1")
    with client:
        first = client.post("/api/translate", json={"domain": "taxi", "description": VAGUE}).json()
        q = first["questions"][0]
        assert set(q) == {"situation", "text", "choices"} and {c["do"] for c in q["choices"]} == set(get_domain("taxi").vocab.actions)
        answer = {"situation": q["situation"], "do": "wait"}
        second = client.post("/api/translate", json={"domain": "taxi", "description": VAGUE, "answers": [answer]}).json()
    from nl2policy.trees import parse_tree

    assert parse_tree(second["tree"], get_domain("taxi").vocab).act(q["situation"]) == "wait"  # acts as answered
    out = CliRunner().invoke(cli, ["translate", "--domain", "taxi", "--json", "--answer", json.dumps(answer), VAGUE])
    assert out.exit_code == 0, out.output
    assert json.loads(out.stdout)["tree"] == second["tree"]
    assert json.loads(CliRunner().invoke(cli, ["translate", "--domain", "taxi", "--json", VAGUE]).stdout)["questions"][0] == q


def test_parse_answers_takes_at_most_max_questions():
    s = _asked()
    with pytest.raises(BadAnswer, match="at most 0"):
        parse_answers("taxi", [{"situation": s, "do": "wait"}], max_questions=0)


def test_the_confidence_after_answers_is_the_trees_probability_given_them():
    """Bayes' rule over the beams: three trees of probability 0.5, 0.3 and 0.1 (0.1 unseen).
    An answer that the 0.3 tree breaks and the others keep leaves 0.5 of 0.5 + 0.1 + 0.1 x 0.6/0.9
    (the unseen 0.1 counted at the rate the beam keeps: 0.6 of 0.9). No answer: its probability."""
    from math import isclose, log
    from nl2policy.language.clarify import posterior
    from nl2policy.trees.tokens import from_tokens
    vocab = get_domain("taxi").vocab
    shown = from_tokens("at_city go_airport go_city".split(), vocab)
    city = from_tokens("at_city has_passenger go_village go_airport go_city".split(), vocab)
    airport = from_tokens("at_airport wait at_city go_airport go_city".split(), vocab)
    wide = [(shown, {0: 0.5}, log(0.5)), (city, {0: 0.6, 1: 0.5}, log(0.3)), (airport, {0: 0.1}, log(0.1))]
    assert isclose(posterior(shown, 0.5, [], wide, []), 0.5)
    in_city = next(s for s in situations("taxi") if dict(s)["at_city"] and dict(s)["has_passenger"])
    answer = [Answer(in_city, shown.act(dict(in_city)))]
    assert not agrees(city, answer) and agrees(airport, answer)
    assert isclose(posterior(shown, 0.5, [wide[0], wide[2]], wide, answer), 0.5 / (0.6 + 0.1 * 0.6 / 0.9))


def test_decoding_under_answers_keeps_the_models_own_probabilities():
    """A tree decoded under answers has the probability the model gives it without them: an answer
    decides which trees are built, it does not move probability onto them."""
    loaded = get_model("taxi")
    model = loaded.translator
    text = load_corpus("taxi", rounds=(2,))[0].description
    wide = model.hypotheses(text, None, None, width=16)
    first = wide[0][0]
    other = next(h for h in wide[1:] if any(h[0].act(dict(s)) != first.act(dict(s)) for s in situations("taxi")))
    where = next(s for s in situations("taxi") if other[0].act(dict(s)) != first.act(dict(s)))
    from nl2policy.language.clarify import allow_for
    from nl2policy.language.decoding import tree_probability
    held = model.hypotheses(text, None, allow_for("taxi", [Answer(where, other[0].act(dict(where)))]), width=16)
    same = next(h for h in held if h[0] == other[0])
    assert tree_probability(same[1]) == pytest.approx(tree_probability(other[1]), rel=1e-5)
    assert all(tree_probability(h[1]) <= tree_probability(wide[0][1]) + 1e-9 for h in held)  # none made likelier than the best


@pytest.mark.parametrize("domain", ["taxi", "highway"])
def test_the_translator_asks_again_only_while_the_answers_leave_it_unsure(domain):
    """After each answer a question comes exactly when the confidence (the tree's probability given
    the answers) is still under the threshold, a question is left and some situation splits the
    plausible trees."""
    from nl2policy.language.clarify import ASK_BELOW
    loaded = get_model(domain)
    stopped_sure = 0
    for spec in load_corpus(domain, rounds=(2,))[:12]:
        result, answers = translate_with(loaded, domain, spec.description), []
        while result.questions:
            q = result.questions[0]
            answers.append(Answer(q.situation, spec.tree.act(dict(q.situation))))
            result = translate_with(loaded, domain, spec.description, answers)
            if result.questions:
                assert result.confidence < ASK_BELOW
            elif len(answers) < 3 and result.confidence >= ASK_BELOW:
                stopped_sure += 1
    assert stopped_sure >= 1


def test_the_cross_fitted_threshold_never_reads_the_held_out_writers_rows(tmp_path):
    """experiments/clarify_threshold: each writer's threshold is the lowest confidence at which the
    other writers' translations are still the target precision right, so a writer's own errors
    never move it; the report scores each writer with the threshold the others gave."""
    from experiments.clarify_threshold import lowest_threshold, main

    rows = [("taxi", "a", 0.9, True), ("taxi", "a", 0.5, True), ("taxi", "a", 0.4, False),
            ("taxi", "b", 0.8, True), ("taxi", "b", 0.45, True), ("taxi", "b", 0.3, False)]
    assert lowest_threshold(rows, 1.0) == 0.45
    assert lowest_threshold(rows, 0.8) == 0.4  # 4 of the 5 at or above 0.4; at 0.3, 4 of 6
    assert lowest_threshold([("taxi", "a", 0.9, False)], 0.97) is None
    path = tmp_path / "rows.jsonl"
    path.write_text("".join(json.dumps({"fold": f"{d}-v6-new-f0", "id": f"{w}-{i:03d}", "confidence": [p], "exact": [e]}) + "\n"
                            for i, (d, w, p, e) in enumerate(rows)))
    main(["--rows", str(path), "--precision", "1.0", "--out", str(tmp_path / "t.md")])
    report = (tmp_path / "t.md").read_text()
    # a's threshold comes from b alone (0.45), b's from a alone (0.5): a keeps 2 rows (both right), b keeps 1
    assert "| a | 0.450 |" in report and "| b | 0.500 |" in report
    assert "| taxi | 6 | 50.0 | 100.0 |" in report
    # a `--data` run's rows (fold "data") name their domain
    path.write_text(json.dumps({"fold": "data", "domain": "highway", "id": "a-000", "confidence": [0.9], "exact": [True]}) + "\n")
    main(["--rows", str(path), "--precision", "1.0", "--out", str(tmp_path / "t.md")])
    assert "| highway | 1 |" in (tmp_path / "t.md").read_text()


def _clarify_row(fold: str, key: str, exact: list, asked: int = 0, gold_questions: int = 2) -> dict:
    return {"fold": fold, "domain": "taxi", "id": key, "questions": ["q"] * asked, "exact": exact, "policy": exact,
            "gold_questions": gold_questions}


def test_committed_rows_are_summarized_over_chosen_folds_and_merged_without_repeats(tmp_path, capsys):
    """experiments.clarify --rows: figures of runs made apart (one fold a session) come from the
    committed rows alone, kept to the folds asked for; a row given twice counts once, and two
    different results for one description of one fold are refused, not averaged."""
    from experiments.clarify import main

    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    a.write_text("".join(json.dumps(r) + "\n" for r in [
        _clarify_row("taxi-v7-new-f0", "w-0", [True, True]), _clarify_row("taxi-v7-new-f0", "w-1", [False, True], 1),
        _clarify_row("taxi-v7-new-f1", "w-2", [False, False], 1, 5)]))
    b.write_text(json.dumps(_clarify_row("taxi-v7-new-f3", "w-3", [False, False], 1)) + "\n" + a.read_text().splitlines()[0] + "\n")
    out = tmp_path / "both"
    main(["--domain", "taxi", "--rows", str(a), "--rows", str(b), "--max-questions", "1", "--out", str(out)])
    got = json.loads((out / "summary.json").read_text())
    assert got["n"] == 4 and got["exact_by_questions"] == [25.0, 50.0] and got["mean_questions"] == 0.75
    assert got["asked_none_share"] == 25.0 and got["asked_none_exact"] == 100.0
    assert sorted(got["by_fold"]) == ["taxi-v7-new-f0", "taxi-v7-new-f1", "taxi-v7-new-f3"]
    assert len((out / "rows.jsonl").read_text().splitlines()) == 4
    # the merged rows summarize to the same figures again, from the output folder itself
    main(["--domain", "taxi", "--rows", str(out / "rows.jsonl"), "--max-questions", "1", "--out", str(out)])
    assert {k: v for k, v in json.loads((out / "summary.json").read_text()).items() if k != "command"} == \
        {k: v for k, v in got.items() if k != "command"}

    main(["--domain", "taxi", "--rows", str(a), "--only-folds", "new-f0", "--max-questions", "1", "--out", str(tmp_path / "f0")])
    only = json.loads((tmp_path / "f0" / "summary.json").read_text())
    assert only["n"] == 2 and only["exact_by_questions"] == [50.0, 100.0] and "by_fold" not in only

    conflict, broken, binary = tmp_path / "c.jsonl", tmp_path / "broken.jsonl", tmp_path / "binary.jsonl"
    conflict.write_text(json.dumps(_clarify_row("taxi-v7-new-f0", "w-0", [False, False])) + "\n")
    broken.write_text(json.dumps(_clarify_row("taxi-v7-new-f0", "w-9", [True, True])) + "\n{not json\n")
    binary.write_bytes(b"\x00\xff\xfe")
    refusals = [
        (["--rows", str(out / "rows.jsonl"), "--only-folds", "f0", "--out", str(out)], "would drop the other folds"),
        (["--rows", str(a), "--only-folds", "f9", "--out", str(tmp_path / "none")], "no rows of the folds"),
        (["--rows", str(a), "--max-questions", "3", "--out", str(tmp_path / "x")], "not made with --max-questions 3"),
        (["--rows", str(a), "--rows", str(conflict), "--out", str(tmp_path / "y")], "has another result"),
        (["--rows", str(broken), "--out", str(tmp_path / "z")], "broken.jsonl:2 is not a row"),
        (["--rows", str(binary), "--out", str(tmp_path / "z")], "cannot read"),
        (["--rows", str(a), "--only-folds", "f0", "--data", str(a), "--out", str(tmp_path / "w")], "give one of"),
        (["--rows", str(a), "--out", str(a / "inside-a-file")], "cannot write the results"),
        (["--folds", str(tmp_path), "--out", str(a / "inside-a-file")], "cannot write into --out folder"),  # before any work
    ]
    for args, needle in refusals:
        with pytest.raises(SystemExit) as exc:
            main(["--domain", "taxi", *([] if "--max-questions" in args else ["--max-questions", "1"]), *args])
        assert exc.value.code == 2
        assert needle in capsys.readouterr().err, needle
    assert len((out / "rows.jsonl").read_text().splitlines()) == 4  # nothing lost by a refusal


def test_every_committed_clarify_summary_is_what_its_committed_rows_say():
    from pathlib import Path

    from experiments.clarify import merge_rows, summarize

    folders = [p.parent for p in (Path(__file__).resolve().parents[1] / "results" / "clarify").glob("**/summary.json")]
    assert folders
    for folder in folders:
        committed = json.loads((folder / "summary.json").read_text())
        domain = json.loads((folder / "rows.jsonl").read_text().splitlines()[0])["fold"].split("-")[0]
        rows = merge_rows([folder / "rows.jsonl"], None, domain)
        again = summarize(rows, len(rows[0]["exact"]) - 1)
        for key in ("n", "exact_by_questions", "policy_by_questions", "mean_questions", "asked_none_share", "asked_none_exact"):
            assert again[key] == committed[key], (folder.name, key)
