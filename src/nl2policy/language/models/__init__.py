"""The translators: one encoder-decoder family whose parts reproduce the paper's models.

Seq2Seq = flat BiGRU encoder + sequential decoder over the pre-order tree tokens;
Seq2Tree = same encoder + binary tree decoder (each node decoded from its parent's state);
Seq2Tree+MiniLM = Seq2Tree whose word inputs are fused with frozen MiniLM layers (ELMo-style);
HAN2Tree = hierarchical (word, sentence) attention encoder + tree decoder;
the default = four Seq2Tree+MiniLM networks trained with synthetic pairs, decoded together under
the grammar with a beam of 4 and checks on the final choice.
Configurations live in `config.py` (with the history of each choice in its comments and in
results/translation/); the network in `network.py`. Variants that lost were deleted with their
code; their recorded folds stay in results/translation/runs.jsonl.
"""

from nl2policy.language.models.config import MODELS, ModelConfig

__all__ = ["MODELS", "ModelConfig"]
