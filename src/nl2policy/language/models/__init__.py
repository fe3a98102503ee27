"""The shipped translator's network and configs.

The network (`network.py`): a flat BiGRU encoder over word embeddings fused with frozen MiniLM
layers (ELMo-style), and a binary tree decoder (each node decoded from its parent's state and
token and its branch). The shipped version is an ensemble of four such networks trained with
synthetic pairs, decoded together under the grammar with a beam of 4 ranked by log-probability
per node; learned findings beside them give the warnings (recipes/v7.toml). The paper's other
translators live in the lab (experiments/translation/baselines.py); variants that lost were
deleted with their code, their recorded folds stay in results/translation/.
"""

from nl2policy.language.models.config import MODELS, ModelConfig

__all__ = ["MODELS", "ModelConfig"]
