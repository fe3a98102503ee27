"""The paper's baseline translators, for Table 1 (Tambwekar et al., RA-L 2023), and the parts of
the shipped default that the lab measures on their own.

Seq2Seq = flat BiGRU encoder + sequential decoder over the pre-order tree tokens;
Seq2Tree = same encoder + the binary tree decoder (each node decoded from its parent's state);
Seq2Tree+MiniLM = Seq2Tree whose word inputs are fused with frozen MiniLM layers (standing in
for BERT); HAN2Tree = hierarchical (word, sentence) attention encoder + tree decoder.

The product ships only the flat encoder with the tree decoder (language/models/network.py);
importing this module registers the two other architectures and these configs, so the lab's
commands train and decode them with the product's own training loop and beam search.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import torch
import torch.nn as nn


from nl2policy.language.models.config import MODELS, ModelConfig, load_recipe
from nl2policy.language.models.network import ARCHITECTURES, Batch, Translator, _bigru_packed, _masked_mean


def _pad1(x: torch.Tensor) -> torch.Tensor:
    """Append one zero position on axis 1, the target of padding indices."""
    return torch.cat([x, x.new_zeros(x.shape[0], 1, *x.shape[2:])], 1)


class HierarchicalTranslator(Translator):
    """HAN2Tree's encoder: a word BiGRU per sentence with word attention, a sentence BiGRU over
    the sentence vectors; the decoder attends to sentences, then to words within them."""

    stackable = False

    def _build_encoder(self, mem: int) -> int:
        h = self.cfg.hidden
        self.word_att = nn.Linear(mem, 1)
        self.sent_gru = nn.GRU(mem, h, batch_first=True, bidirectional=True)
        self.sent_att = nn.Linear(h, mem, bias=False)
        return 2 * mem

    def encode(self, b: Batch) -> dict:
        x = self._inputs(b)
        mask = b.words != 0
        B, S, W = b.sent_index.shape
        grid_index = b.sent_index.view(B, S * W, 1)
        word_mask = torch.arange(W)[None, None] < b.sent_lengths[..., None]  # (B, S, W)
        # one BiGRU pass per sentence, then back to the flat word axis
        xs = torch.gather(_pad1(x), 1, grid_index.expand(-1, -1, x.shape[-1])).view(B * S, W, -1)
        grid = _bigru_packed(self.word_gru, xs, b.sent_lengths.view(-1)).view(B, S * W, -1)
        flat = torch.zeros(B, x.shape[1] + 1, grid.shape[-1]).scatter(1, grid_index.expand(-1, -1, grid.shape[-1]), grid)
        states = self.drop(flat[:, :-1])
        grid = self.drop(grid).view(B, S, W, -1)
        att = self.word_att(grid).squeeze(-1).masked_fill(~word_mask, -1e9)
        sent_vec = (torch.softmax(att, -1).unsqueeze(-1) * grid).sum(2)
        sent_states = self.drop(_bigru_packed(self.sent_gru, sent_vec, b.n_sents))
        sent_mask = torch.arange(S)[None] < b.n_sents[:, None]
        return {"words": states, "mask": mask, "grid_index": b.sent_index, "word_mask": word_mask,
                "sents": sent_states, "sent_mask": sent_mask,
                "h0": torch.tanh(self.init(_masked_mean(sent_states, sent_mask)))}

    def attend(self, memory: dict, h: torch.Tensor) -> torch.Tensor:
        """P(sentence) * P(word | sentence), normalised on the (sentence, word) grid."""
        q = self.word_query(h)
        words = memory["words"]
        score = torch.einsum("bnd,bd->bn", words, q)
        B, S, W = memory["grid_index"].shape
        s_att = torch.softmax(torch.einsum("bsd,bd->bs", memory["sents"], q).masked_fill(~memory["sent_mask"], -1e9), -1)
        grid_score = torch.gather(_pad1(score), 1, memory["grid_index"].view(B, -1)).view(B, S, W)
        grid_att = torch.softmax(grid_score.masked_fill(~memory["word_mask"], -1e9), -1) * s_att[..., None]
        flat_att = torch.zeros(B, words.shape[1] + 1).scatter_add(1, memory["grid_index"].view(B, -1), grid_att.view(B, -1))
        return torch.cat([torch.einsum("bs,bsd->bd", s_att, memory["sents"]),
                          torch.einsum("bn,bnd->bd", flat_att[:, :-1], words)], -1)


class SequentialTranslator(Translator):
    """Seq2Seq's decoder: the state runs on from the previous token only (no parent token,
    parent state or branch)."""

    stackable = False

    def step(self, memory: dict, h_prev: torch.Tensor, ctx_prev: torch.Tensor, prev_tok: torch.Tensor,
             h_parent: torch.Tensor, parent_tok: torch.Tensor, branch: torch.Tensor):
        return super().step(memory, h_prev, ctx_prev, prev_tok, torch.zeros_like(h_parent),
                            torch.full_like(parent_tok, self.start_id), torch.zeros_like(branch))


ARCHITECTURES[("han", "tree")] = HierarchicalTranslator
ARCHITECTURES[("flat", "seq")] = SequentialTranslator

BASELINES: dict[str, ModelConfig] = {
    # the paper's four translators (Table 1), MiniLM standing in for BERT
    "seq2seq": ModelConfig("flat", "seq", False, 0),
    "seq2tree": ModelConfig("flat", "tree", False, 0),
    "seq2tree-minilm": ModelConfig("flat", "tree", True, 0, minilm_layers=6),
    "han2tree": ModelConfig("han", "tree", False, 0),
    # one of the default's networks: seq2tree-minilm with synthetic random-tree pairs
    "seq2tree-minilm-synth": ModelConfig("flat", "tree", True, 200, minilm_layers=6),
    # the default's four networks (member m: seed s + m, its own draw of augmented and synthetic
    # pairs), step probabilities averaged, a beam of 4: the default without its learned findings.
    # The variants that lost were deleted with their code; their folds stay in
    # results/translation/history/runs.jsonl and history.md
    "seq2tree-minilm-synth-x4": ModelConfig("flat", "tree", True, 200, minilm_layers=6, ensemble=4,
                                            member_draws=True, beam=4),
}
MODELS.update(BASELINES)
# Recipes of earlier shipped versions and candidates (recipes/ beside this file; the product holds
# the shipped one alone). v3, shipped until v7: the lab still measures it and reads its kept networks.
RECIPES = Path(__file__).resolve().parent / "recipes"
MODELS["v3"] = load_recipe("v3", RECIPES)
# The candidate after v3 (experiments/translation/ensemble_probe.py found v2's and v3's networks
# together beat v3 on leave-trees-out and kept v2's level on the CV folds it could run): eight
# members, alternately 1,000 synthetic pairs (v3's) and 200 (v2's); member 0's draw, and so the
# learned findings, is v3's kind.
MODELS["v3-mix200"] = replace(MODELS["v3"], synthetic=(1000, 200), ensemble=8)
# The candidate for v4 (measured against v3; it did not ship).
MODELS["v4"] = load_recipe("v4", RECIPES)
# The candidate after v4 (recipes/v6.toml; it did not ship, v7 did): v4's generator,
# 4,000 synthetic pairs a member, 10 epochs, the beam ranked per node, the findings for the
# warnings alone. Measured on NWNT from kept fold networks (results/translation/nwnt/).
MODELS["v6"] = load_recipe("v6", RECIPES)
# v6 under the name it was measured as first (history/length_norm/, the clarify history): those
# commands still run.
MODELS["v5-mean"] = MODELS["v6"]
# v6 with the corpus weighed as v3 weighs it: v6 reads each real description 20 times (10 epochs, the
# description and one augmented copy) against v3's 60 (30 epochs x 2), and lost 16 points to v3 on
# leave-writers-out (results/translation/lwo/). Five augmented copies give v6's 10 epochs v3's 60
# readings while keeping v6's 40,000 synthetic ones. Judged on leave-writers-out and NWNT together.
# Shipped since 2026-12-07: the product registers it as DEFAULT_MODEL (recipes/v7.toml).
