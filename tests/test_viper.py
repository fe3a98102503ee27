"""VIPER, Table 2's distillation baseline (experiments/policy/viper.py): one tiny run end to end
(the exact tree fit it uses is tested in test_distill.py)."""

import pytest

from experiments.policy.viper import run_viper
from nl2policy.domains import get_domain
from nl2policy.trees.parse import validate


@pytest.mark.train
def test_a_tiny_viper_run_returns_a_valid_tree_and_resumes(tmp_path):
    result = run_viper("taxi", seed=0, steps=2048, run_dir=tmp_path / "v", rounds=2, steps_per_round=1024)
    d = get_domain("taxi")
    from nl2policy.trees import parse_tree
    validate(parse_tree(result["tree"], d.vocab), d.vocab)
    assert len(result["rounds"]) == 2 and result["judged_by"] == "exact expected return"
    assert result["score"] == max(r["score"] for r in result["rounds"])
    assert (tmp_path / "v" / "teacher.zip").is_file()
    assert run_viper("taxi", seed=0, steps=2048, run_dir=tmp_path / "v", rounds=2, steps_per_round=1024) == result
