"""The Table-2 runner on a toy budget: tree selection, finished runs skipped, table written."""

import json

import pytest
import numpy as np
from typer.testing import CliRunner

from experiments.policy.__main__ import app
from experiments.policy.table2 import _reach, parse_knobs, steps_to
from nl2policy.policy.optimize import rolling_mean

pytestmark = pytest.mark.train

runner = CliRunner()


def test_rolling_mean_uses_the_last_window_episodes():
    assert np.allclose(rolling_mean([1, 2, 3, 4], 2), [1, 1.5, 2.5, 3.5])


def test_steps_to_a_level_and_the_median_over_runs_that_never_reach_it():
    assert steps_to([(0, 1.0), (10, 2.0), (20, 3.0)], 2.0) == 10
    assert steps_to([(0, 1.0)], 2.0) is None
    assert _reach([10, 30, None])["median"] == 30  # a run that never reached counts as slowest
    assert _reach([10, None, None]) == {"median": None, "reached": 1, "runs": 3, "values": [10, None, None]}


def test_knobs_changed_for_a_grid_are_typed_and_checked(tmp_path):
    assert parse_knobs(["train_envs=8", "leaf_mass = 0.9"]) == {"train_envs": 8, "leaf_mass": 0.9}
    for bad in (["leaf_mas=0.9"], ["leaf_mass"], ["leaf_mass=zero"]):
        with pytest.raises(ValueError, match="--knob"):
            parse_knobs(bad)
    result = runner.invoke(app, ["table2", "--domain", "taxi", "--knob", "gamma=1", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--knob 'gamma=1'" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "taxi").exists()


def test_tiny_experiment_writes_table_and_skips_finished_runs(tmp_path):
    args = ["table2", "--domain", "taxi", "--steps", "512", "--candidates", "3", "--best", "1",
            "--select-episodes", "5", "--tree-seeds", "1", "--baseline-seeds", "1", "--out", str(tmp_path)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    table = json.loads((tmp_path / "table2_taxi.json").read_text())
    assert {r["method"] for r in table["runs"]} == {"tree_ddt", "random_ddt", "mlp"}
    assert (tmp_path / "curves_taxi.png").is_file() and "--steps 512" in (tmp_path / "table2_taxi.md").read_text()
    selected = json.loads((tmp_path / "taxi" / "selected_trees.json").read_text())
    returns = [c["exact_return"] for c in selected["candidates"]]  # taxi ranks by the exact return
    assert returns == sorted(returns, reverse=True) and selected["selected"] == selected["candidates"][:1]
    runs = {r["method"]: r for r in table["runs"]}
    ceiling = table["table"]["yardsticks"]["ceiling"]["value"]
    assert abs(ceiling - 8.386) < 1e-3  # the best stationary feature policy (results/policy/ceilings_taxi.md)
    y = table["table"]["yardsticks"]
    assert max(y["floor"]["value"], y["constant"]["value"]) < ceiling  # taxi: every state-blind policy earns 0
    assert abs(table["table"]["reach_return"] - (y["floor"]["value"] + 0.9 * (ceiling - y["floor"]["value"]))) < 1e-12
    tree_run = runs["tree_ddt"]
    # the probe at step 0 scores the start tree itself (the fresh DDT discretizes back to it)
    assert tree_run["probes"][0] == {"step": 0, **tree_run["probes"][0]}
    assert abs(tree_run["probes"][0]["policy"] - tree_run["initial_tree_score"]) < 1e-9
    assert tree_run["initial_tree_score"] <= tree_run["kept_score"] <= tree_run["polished_score"] + 1e-12
    # the last probe scores the tree handed back as PPO's last (the better reading of the last checkpoint)
    from nl2policy.domains import get_domain
    from nl2policy.policy.convert import tree_act_fn
    from nl2policy.policy.keep_best import tree_from_json

    assert tree_run["last_read"] in ("rounded", "distilled")
    last = tree_act_fn("taxi", tree_from_json(tree_run["last_tree"]))
    assert tree_run["probes"][-1]["policy"] == pytest.approx(get_domain("taxi").exact.expected_return(last), abs=1e-9)
    for r in table["runs"]:  # every handed-back policy maps features to actions: none beats the ceiling
        assert len(r["probes"]) >= 2 and all(p["policy"] <= ceiling + 1e-9 for p in r["probes"])
        assert abs(r["soft_minus_discrete"] - (r["probes"][-1]["soft"] - r["probes"][-1]["policy"])) < 1e-12
    md = (tmp_path / "table2_taxi.md").read_text()
    assert "steps to 90%" in md and (tmp_path / "table2_taxi_runs.md").is_file()
    run = tmp_path / "taxi" / "runs" / "mlp_s0" / "result.json"
    before = run.stat().st_mtime_ns
    assert runner.invoke(app, args).exit_code == 0  # second time: every run already finished
    assert run.stat().st_mtime_ns == before
    assert json.loads((tmp_path / "table2_taxi.json").read_text())["table"] == table["table"]
    # VIPER's teacher is the MLP run of the same seed trained again: the same network, so the same return
    viper = runner.invoke(app, ["viper", "--domain", "taxi", "--seeds", "1", "--rounds", "1", "--steps-per-round", "256",
                                "--out", str(tmp_path)])
    assert viper.exit_code == 0, viper.output
    distilled = json.loads((tmp_path / "taxi" / "viper" / "viper_s0" / "result.json").read_text())
    assert distilled["teacher_steps"] == runs["mlp"]["steps"]
    assert distilled["teacher_judged"] == runs["mlp"]["probes"][-1]["policy"]
    assert runner.invoke(app, args).exit_code == 0
    assert "VIPER" in (tmp_path / "table2_taxi.md").read_text()


def test_sampled_probe_scores_the_start_tree_on_the_probe_scenes():
    """Highway has no exact model: the probe plays the handed-back policy on probe_episodes("highway")
    common scenes of the twin; at step 0 a tree-DDT hands back its start tree, so the probe's
    return is the tree's own on those scenes, and the soft policy's is a different number."""
    from nl2policy.domains import get_domain
    from nl2policy.language.corpus import load_corpus
    from nl2policy.policy.convert import tree_batch_act_fn
    from experiments.policy.table2 import policy_probe, probe_episodes
    from nl2policy.policy.optimize import EVAL_SEED
    from nl2policy.policy.rollout import evaluate_batched
    from nl2policy.policy.sb3_policy import make_ppo

    tree = load_corpus("highway")[0].tree
    model = make_ppo("highway", "tree_ddt", 0, tree)
    probe = policy_probe("highway", "tree_ddt")(model)
    own = evaluate_batched("highway", tree_batch_act_fn("highway", tree), probe_episodes("highway"), EVAL_SEED).mean_return
    assert probe["policy"] == own and probe["soft"] != own
    mlp = policy_probe("highway", "mlp")(make_ppo("highway", "mlp", 0))
    assert set(mlp) == {"policy", "soft"} and get_domain("highway").exact is None


def test_the_paper_sentence_calls_a_method_level_only_within_two_standard_errors():
    from experiments.policy.table2_report import paper_comparison

    def stats(median, stderr=0.1):
        return {"median": median, "stderr": stderr, "mean": median}

    yardsticks = {"floor": {"value": 0.0}, "ceiling": {"value": 10.0}}
    reach = {"median": 0, "reached": 2, "runs": 2, "values": [0, None]}
    table = {"yardsticks": yardsticks, "reach_level": 0.9,
             "tree_ddt": {"initial": stats(6.0), "best": stats(9.0), "steps_to_reach_policy": reach},
             "random_ddt": {"initial": stats(1.0), "best": stats(8.8)},  # 0.2 apart < 2 * 0.141: level
             "mlp": {"initial": stats(1.0), "best": stats(9.5),  # 0.5 apart: below
                     "steps_to_reach_policy": {"median": 45000, "reached": 3, "runs": 3, "values": [1, 2, 3]}}}
    text = paper_comparison(table, 1000)
    assert "initial rolling reward (normalized: 60%) is above the random DDT (8 leaves)'s (10%)" in text
    assert "is level with the random DDT (8 leaves) (88%)" in text and "below the MLP (3 layers) (95%)" in text
    assert "from the first step in 1 of 2 runs" in text and "a median of 45k steps (3 of 3 runs ever do)" in text
    assert paper_comparison({k: v for k, v in table.items() if k != "mlp"}, 1000) is None


def test_highway_trees_are_judged_on_the_probe_scenes_not_the_ones_that_chose_them():
    """Keep-best and the polish choose on tree_scorer's scenes; Table 2 re-scores the start, kept
    and polished trees on the probe's scenes, once (a finished run gains the scores when read)."""
    from nl2policy.language.corpus import load_corpus
    from nl2policy.policy.convert import tree_batch_act_fn
    from experiments.policy.table2 import judge_trees, probe_episodes, summarize
    from nl2policy.policy.keep_best import tree_scorer
    from nl2policy.policy.optimize import EVAL_SEED
    from nl2policy.policy.rollout import evaluate_batched
    from nl2policy.trees import tree_to_json

    specs = load_corpus("highway")
    start, other = specs[0].tree, next(s.tree for s in specs if s.tree != specs[0].tree)
    chosen_on = tree_scorer("highway")[0]
    result = {"method": "tree_ddt", "tree": tree_to_json(start), "initial_tree_score": chosen_on(start),
              "kept_tree": tree_to_json(start), "kept_score": chosen_on(start),
              "polished_tree": tree_to_json(other), "polished_score": chosen_on(other)}
    assert judge_trees("highway", result) and not judge_trees("highway", result)  # once
    probe = {t: evaluate_batched("highway", tree_batch_act_fn("highway", t), probe_episodes("highway"), EVAL_SEED).mean_return
             for t in (start, other)}
    assert result["kept_judged"] == result["initial_tree_judged"] == probe[start]
    assert result["polished_judged"] == probe[other] and result["kept_judged"] != result["kept_score"]
    row = {**result, "window": 1, "curve": [[1, 0.0]], "initial": 0.0, "best": 0.0, "final": 0.0}
    table = summarize([row], "highway", {"floor": {"value": 0.0}, "ceiling": {"value": 1.0}})
    assert table["tree_ddt"]["polished_score"]["median"] == probe[other]
    assert not judge_trees("taxi", {"method": "tree_ddt", "kept_tree": tree_to_json(load_corpus("taxi")[0].tree)})


def test_weak_taxi_starts_are_distinct_corpus_policies_below_the_bar():
    """Issue 45's weak starts: frequent corpus policies below WEAK_BELOW, one per exact return,
    spanning the returns the issue's runs started from (6.21, 4.87, 0.00)."""
    from experiments.taxi_never_worse import WEAK_BELOW, starts, weak_starts

    weak = weak_starts()
    values = [round(s["exact"], 4) for s in weak]
    assert all(v < WEAK_BELOW for v in values) and len(set(values)) == len(values)
    assert {6.2057, 4.8665, 0.0} <= set(values)
    frequent = {round(s["exact"], 4) for s in starts(lowest=0)}
    assert {v for v in frequent if v < WEAK_BELOW} == set(values)  # none left out


def test_a_climbed_ceiling_is_shown_only_when_scored_on_the_probes_own_scenes(tmp_path):
    from experiments.policy.table2 import EVAL_SEED, probe_episodes
    from experiments.policy.table2_report import climbed_ceiling

    assert (probe_episodes("lunar"), EVAL_SEED) == (100, 50000)  # the scenes the files below name

    assert climbed_ceiling(tmp_path, "lunar") is None  # no ceilings file
    climbs = [{"start_name": "a", "fresh": {"mean": -50.0, "stderr": 2.0}},
              {"start_name": "b", "fresh": {"mean": -30.0, "stderr": 3.0}}]
    path = tmp_path / "ceilings_lunar.json"
    path.write_text(json.dumps({"climbs": climbs, "best": 1, "max_depth": 3, "eval_episodes": 100, "eval_seed": 50000}))
    assert climbed_ceiling(tmp_path, "lunar") == {"mean": -30.0, "stderr": 3.0, "max_depth": 3, "start": "b"}
    path.write_text(json.dumps({"climbs": climbs, "best": 1, "max_depth": 3, "eval_episodes": 100, "eval_seed": 7}))
    assert climbed_ceiling(tmp_path, "lunar") is None  # other scenes: not comparable
    path.write_text(json.dumps({"climbs": climbs, "best": 1, "max_depth": 3, "eval_episodes": 20, "eval_seed": 50000}))
    assert climbed_ceiling(tmp_path, "lunar") is None
    path.write_text(json.dumps({"optimum": 8.4}))  # an exact ceiling is the table's own yardstick
    assert climbed_ceiling(tmp_path, "lunar") is None


def _example_run(folder, tree: dict, seed: int, kept: float, polished, start: float = -70.0) -> None:
    """A finished tree-DDT run folder as `table2` leaves it, with only what the example reads."""
    run = {"seed": seed, "steps": 1000, "tree": tree, "kept_tree": tree, "kept_score": kept, "kept_judged": kept - 1,
           "initial_tree_judged": start, "judged_by": "10 test episodes"}
    if polished is not None:
        run.update(polished_tree={"do": "main_engine"}, polished_score=polished, polished_judged=polished - 1)
    path = folder / "lunar" / "runs" / f"tree_ddt_t0_s{seed}"
    path.mkdir(parents=True)
    (path / "result.json").write_text(json.dumps(run))


def test_the_worked_example_gathers_the_runs_that_start_from_the_example_tree(tmp_path):
    from experiments.policy.example import NoExampleRuns, write_example
    from nl2policy.domains import get_domain
    from nl2policy.trees.parse import tree_to_json

    with pytest.raises(NoExampleRuns, match="no finished tree-DDT run"):
        write_example("lunar", tmp_path, "cmd")
    start = tree_to_json(get_domain("lunar").example_tree)
    _example_run(tmp_path, start, 0, kept=-70.0, polished=-20.0)   # handed back: polished, judged -21
    _example_run(tmp_path, start, 1, kept=-60.0, polished=None)    # handed back: kept, judged -61
    _example_run(tmp_path, start, 2, kept=-50.0, polished=-80.0)   # polish lost: kept, judged -51
    _example_run(tmp_path, {"do": "nothing"}, 3, kept=0.0, polished=None)  # another start: not this example
    text = write_example("lunar", tmp_path, "cmd").read_text()
    assert "seed 0: -21.0, seed 1: -61.0, seed 2: -51.0;" in text and "seed 3" not in text
    assert "better than the start in 3 of 3" in text
    assert "run with the median return of the tree handed back, seed 2" in text
    assert "Made by: `cmd`" in text


def test_the_readme_quotes_the_committed_worked_example():
    """The README's lunar example is the one `python -m experiments.policy example` wrote, not typed in."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    report = (root / "results" / "policy" / "example_lunar.md").read_text()
    readme = (root / "README.md").read_text()
    blocks = re.findall(r"```text\n(.*?)```", report, re.S)
    assert len(blocks) == 2 and all(block in readme for block in blocks)
    for number in re.findall(r"\*\*(-?[\d.]+)\*\*", report):
        assert number in readme
