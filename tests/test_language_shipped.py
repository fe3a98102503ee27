"""The shipped default translators: a fresh install translates without training first."""

import pytest

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.language import translate as tr
from nl2policy.language.corpus import load_corpus
from nl2policy.language.models.config import DEFAULT_MODEL
from nl2policy.trees.parse import validate


@pytest.fixture
def empty_home(tmp_path, monkeypatch, one_torch_thread):
    monkeypatch.setenv("NL2POLICY_HOME", str(tmp_path))
    tr._LOADED.clear()
    yield tmp_path
    tr._LOADED.clear()


@pytest.mark.parametrize("domain", DOMAINS)
def test_default_model_is_shipped(domain):
    path = tr.shipped_path(domain)
    assert path == get_domain(domain).folder / f"translator-{DEFAULT_MODEL}.pt"
    assert path.is_file(), "run the command in src/nl2policy/domains/README.md"
    assert path.stat().st_size < 6_000_000
    import torch

    from nl2policy.language.models.config import MODELS, ModelConfig

    saved = torch.load(path, weights_only=False)["cfg"]
    # read as load_model reads it: a config field added after the file was saved takes its
    # default, which by design is the behaviour from before the field existed
    assert set(saved) <= set(MODELS[DEFAULT_MODEL].to_dict()), "the shipped model has fields this version lacks"
    from nl2policy.language.shipping import shipped_config

    expected = shipped_config(domain)  # the recipe with the domain's [translator] settings, if any
    assert ModelConfig(**saved) == expected, "the shipped model is stale: retrain it (see its README)"


@pytest.mark.parametrize("domain", DOMAINS)
def test_translate_uses_the_shipped_model_without_training(domain, empty_home, monkeypatch):
    def no_training(*args, **kwargs):
        raise AssertionError("translate() trained a model although one is shipped")

    from nl2policy.language import shipping

    monkeypatch.setattr(shipping, "train_default", no_training)
    assert tr.find_model(domain) == tr.shipped_path(domain)
    # what it was trained on: the corpus, or for a domain nobody has described the synthetic pairs
    from nl2policy.language.synthetic import synthetic_pairs

    pairs = [(s.description, s.tree) for s in load_corpus(domain)] or synthetic_pairs(domain, 20, 0, [])
    result = tr.translate(domain, pairs[0][0])  # no training: train_default raises above
    validate(result.tree, get_domain(domain).vocab)
    assert 0.0 <= result.confidence <= 1.0
    # it must reproduce most of a few training trees
    right = sum(tr.translate(domain, text).tree == tree for text, tree in pairs[:20])
    assert right >= 14
    assert not list(empty_home.glob("models/*.pt"))


def test_user_model_takes_precedence_over_the_shipped_one(empty_home):
    user = empty_home / "models" / f"taxi-{DEFAULT_MODEL}.pt"
    user.parent.mkdir(parents=True)
    user.write_bytes(b"")
    assert tr.find_model("taxi") == user


def test_the_shipped_version_is_one_small_recipe_file_and_a_bad_setting_is_named(tmp_path, monkeypatch):
    from nl2policy.language.models import config

    assert config.DEFAULT_MODEL == "v7" and config.MODELS["v7"] == config.load_recipe("v7")
    assert len((config.RECIPES / "v7.toml").read_text().splitlines()) < 40
    # the learned findings train beside the networks for the warnings (no pattern check) and do
    # not steer the beam
    assert config.MODELS["v7"].findings and config.MODELS["v7"].findings_cost == 0
    (tmp_path / "v9.toml").write_text('encoder = "flat"\ndecoder = "tree"\nminilm = true\nsynthetic = 0\nbeam_width = 3\n')
    monkeypatch.setattr(config, "RECIPES", tmp_path)
    with pytest.raises(ValueError, match="unknown settings beam_width"):
        config.load_recipe("v9")


def test_the_product_holds_only_the_shipped_architecture_and_never_imports_the_lab():
    """The paper's baselines live in experiments/ (the lab); the product names them clearly."""
    import subprocess
    import sys

    code = ("import sys, nl2policy.cli, nl2policy.language.translate\n"
            "from nl2policy.language.models.config import DEFAULT_MODEL, MODELS, ModelConfig\n"
            "from nl2policy.language.models.network import build_network\n"
            "assert not any(m.startswith('experiments') for m in sys.modules), 'the product imported the lab'\n"
            "assert set(MODELS) == {DEFAULT_MODEL, 'smoke'}, sorted(MODELS)\n"
            "try:\n    build_network(ModelConfig('han', 'tree', False, 0), 10, 5)\n"
            "except ValueError as exc:\n    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "no network for encoder 'han' with decoder 'tree'" in out.stdout and "experiments/translation" in out.stdout


def test_no_module_of_the_package_imports_ray_or_the_lab():
    """The product is what a user runs: grids (Ray), harnesses and report writers live in
    experiments/. Every import statement counts, also those inside functions (run lazily)."""
    import ast
    from pathlib import Path

    import nl2policy

    offenders = []
    for path in sorted(Path(nl2policy.__file__).parent.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in ("ray", "experiments")]
    assert offenders == []
