"""Each domain's knobs live in its spec: read into typed fields, strict about typos, passed
down explicitly (overrides by dataclasses.replace, no module globals), and the exact model
is a capability of the domain."""

import dataclasses
import shutil

import numpy as np
import pytest

from nl2policy.domains import get_domain
from nl2policy.domains.spec import Knobs, PPOSettings, load_domain
from nl2policy.policy.convert import tree_to_ddt
from nl2policy.policy.sb3_policy import make_ppo
from nl2policy.trees import Leaf, Node

TREE = Node("has_passenger", Leaf("go_airport"), Leaf("go_city"))


@pytest.mark.parametrize("name", ["taxi", "highway"])
def test_knobs_are_typed_fields_of_the_spec(name):
    knobs = get_domain(name).knobs
    assert isinstance(knobs, Knobs) and isinstance(knobs.ppo, PPOSettings)
    assert 0 < knobs.leaf_mass < 1 and knobs.ddt_gamma > 0 and knobs.eval_episodes >= 1
    assert isinstance(knobs.ppo.n_steps, int) and isinstance(knobs.fidelity_gammas, tuple)


def test_a_typo_in_the_knobs_is_an_error_not_a_default(tmp_path):
    folder = tmp_path / "taxi"
    shutil.copytree(get_domain("taxi").folder, folder)
    text = (folder / "spec.toml").read_text().replace("leaf_mass = 0.7", "leaf_mas = 0.7")
    (folder / "spec.toml").write_text(text)
    with pytest.raises(ValueError, match=r"taxi/spec.toml.*unknown keys \['leaf_mas'\], missing keys \['leaf_mass'\]"):
        load_domain(folder, "nl2policy.domains.taxi")


def test_exact_model_is_a_capability_of_the_domain():
    taxi, highway = get_domain("taxi"), get_domain("highway")
    assert highway.exact is None
    act = lambda x: 0 if x[3] > 0.5 else 2  # noqa: E731 - passenger -> airport, else city
    assert 6.0 < taxi.exact.expected_return(act) < taxi.exact.optimum()


def test_overridden_knobs_reach_the_ddt_and_ppo_without_touching_the_domains():
    base = get_domain("taxi").knobs
    knobs = dataclasses.replace(base, leaf_mass=0.95, actor_lr_scale=2.0,
                                ppo=dataclasses.replace(base.ppo, ent_coef=0.0, n_steps=256))
    probs = tree_to_ddt("taxi", TREE, knobs=knobs).leaf_logits.softmax(-1).max(-1).values
    assert np.allclose(probs.detach().numpy(), 0.95)
    model = make_ppo("taxi", "tree_ddt", seed=0, tree=TREE, knobs=knobs)
    assert model.n_steps == 256 and model.ent_coef == 0.0
    assert sorted(g["lr_scale"] for g in model.policy.optimizer.param_groups) == [1.0, 2.0]
    assert get_domain("taxi").knobs == base  # nothing global changed
    default = make_ppo("taxi", "tree_ddt", seed=0, tree=TREE)
    assert default.n_steps == base.ppo.n_steps and default.ent_coef == base.ppo.ent_coef


def test_uniform_taxi_states_have_one_place():
    states = get_domain("taxi").uniform_states(1000, seed=3)
    assert set(np.unique(states)) <= {0.0, 1.0}
    assert (states[:, :3].sum(axis=1) == 1).all()
    assert 0.3 < states[:, 3:].mean() < 0.7
