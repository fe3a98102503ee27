"""The shipped translator's network: a flat BiGRU encoder over word embeddings (fused with frozen
MiniLM layers) and a binary tree decoder (see models/__init__.py). The paper's other
architectures (hierarchical encoder, sequential decoder) are subclasses in the lab
(experiments/translation/baselines.py), which registers them in `ARCHITECTURES`.

Training is teacher-forced over the gold pre-order tokens; each step's softmax is taken only
over the tokens the grammar allows there, in training and decoding alike, so the model never
spends probability on invalid trees and its sequence probability is a usable confidence.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import torch
import torch.nn as nn
from torch.nn.utils.rnn import pack_padded_sequence, pad_packed_sequence

from nl2policy.language.models.config import ModelConfig
from nl2policy.language.models.pretrained import DIM as MINILM_DIM


@dataclass
class Batch:
    """Padded inputs. `words` (B, N) token ids; `sent_index` (B, S, W) positions into the
    N axis (N = padding) for the hierarchical encoder."""

    words: torch.Tensor
    lengths: torch.Tensor
    mini: Optional[torch.Tensor]  # (B, layers, N, 384) frozen MiniLM states, or None
    sent_index: torch.Tensor
    sent_lengths: torch.Tensor  # (B, S) words per sentence (0 = padding sentence)
    n_sents: torch.Tensor  # (B,)


def _bigru_packed(gru: nn.GRU, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    if bool((lengths >= x.shape[1]).all()):  # no padding (one description at a time): packing is pure overhead
        return gru(x)[0]
    packed = pack_padded_sequence(x, lengths.clamp(min=1).cpu(), batch_first=True, enforce_sorted=False)
    out, _ = gru(packed)
    out, _ = pad_packed_sequence(out, batch_first=True, total_length=x.shape[1])
    return out


def _masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    m = mask.unsqueeze(-1).float()
    return (x * m).sum(1) / m.sum(1).clamp(min=1)


class Translator(nn.Module):
    """Flat encoder + tree decoder. A subclass changes the encoder (`_build_encoder`, `encode`,
    `attend`) or the decoder's inputs (`step`); `stackable` says whether the ensemble's stacked
    encoder and decoder (same arithmetic, batched over members) may stand in for it."""

    stackable = True

    def __init__(self, cfg: ModelConfig, n_words: int, n_tree_tokens: int) -> None:
        super().__init__()
        self.cfg = cfg
        h, e = cfg.hidden, cfg.embed
        self.word_emb = nn.Embedding(n_words, e, padding_idx=0)
        in_dim = e
        if cfg.minilm:  # ELMo-style: softmax-weighted sum of layers, scaled by gamma
            self.mix_logits = nn.Parameter(torch.zeros(cfg.minilm_layers + 1))
            self.mix_gamma = nn.Parameter(torch.ones(()))
            self.mini_norm = nn.LayerNorm(MINILM_DIM)  # BERT states have a few huge dimensions
            self.mini_proj = nn.Linear(MINILM_DIM, 2 * e)
            in_dim += 2 * e
        self.drop = nn.Dropout(cfg.dropout)
        self.word_gru = nn.GRU(in_dim, h, batch_first=True, bidirectional=True)
        mem = 2 * h
        ctx_dim = self._build_encoder(mem)
        self.init = nn.Linear(mem, h)
        self.tok_emb = nn.Embedding(n_tree_tokens + 1, e)  # last id: the root's "start"
        self.branch_emb = nn.Embedding(3, e)
        self.cell = nn.GRUCell(3 * e + h + ctx_dim, h)  # [previous token, parent token, branch, parent state, last context]
        self.word_query = nn.Linear(h, mem, bias=False)
        self.out = nn.Linear(h + ctx_dim, h)
        self.logits = nn.Linear(h, n_tree_tokens)
        self.start_id = n_tree_tokens

    # ---- encoder -------------------------------------------------------------------------
    def _build_encoder(self, mem: int) -> int:
        """Layers an encoder adds after the word BiGRU (none here); returns the attention
        context's width."""
        return mem

    def _inputs(self, b: Batch) -> torch.Tensor:
        x = self.word_emb(b.words)
        if self.cfg.minilm:
            weights = torch.softmax(self.mix_logits, 0)
            mixed = torch.einsum("l,blnd->bnd", weights, b.mini)
            x = torch.cat([x, self.mini_proj(self.mix_gamma * self.mini_norm(mixed))], -1)
        return self.drop(x)

    def _words(self, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        return _bigru_packed(self.word_gru, x, lengths)

    def encode(self, b: Batch) -> dict:
        x = self._inputs(b)
        return self.flat_memory(self.drop(self._words(x, b.lengths)), b.words != 0)

    def flat_memory(self, states: torch.Tensor, mask: torch.Tensor) -> dict:
        """The flat encoder's memory: its word states and mask, and the decoder's start state."""
        return {"words": states, "mask": mask, "h0": torch.tanh(self.init(_masked_mean(states, mask)))}

    def attend(self, memory: dict, h: torch.Tensor) -> torch.Tensor:
        """The attention context for decoder state h."""
        q = self.word_query(h)  # (B, mem)
        words = memory["words"]
        att = torch.softmax(torch.einsum("bnd,bd->bn", words, q).masked_fill(~memory["mask"], -1e9), -1)
        return torch.einsum("bn,bnd->bd", att, words)

    # ---- decoder -------------------------------------------------------------------------
    def step(self, memory: dict, h_prev: torch.Tensor, ctx_prev: torch.Tensor, prev_tok: torch.Tensor,
             h_parent: torch.Tensor, parent_tok: torch.Tensor, branch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One decoding step: the state takes the previous token, the parent node's token and
        state and which branch (yes/no) this slot is, so each node is decoded knowing where in
        the tree it sits. Returns (state, attention context, unmasked logits)."""
        inp = torch.cat([self.tok_emb(prev_tok), self.tok_emb(parent_tok), self.branch_emb(branch), h_parent, ctx_prev], -1)
        h = self.cell(self.drop(inp), h_prev)
        ctx = self.attend(memory, h)
        return h, ctx, self.logits(self.drop(torch.tanh(self.out(torch.cat([h, ctx], -1)))))

    def run_step(self, memory: dict, hs: list, ctxs: list, toks: list, parent: torch.Tensor, branch: torch.Tensor):
        """The next step given the states so far (hs[0] = h0, toks[0] = start); parent is the
        parent's step index (-1 for the root)."""
        rows = torch.arange(len(parent))
        H, T = torch.stack(hs, 1), torch.stack(toks, 1)
        src = parent + 1  # the root's parent is the start state
        return self.step(memory, hs[-1], ctxs[-1], toks[-1], H[rows, src], T[rows, src], branch)

    def loss(self, b: Batch, targets: torch.Tensor, parents: torch.Tensor, branches: torch.Tensor,
             masks: torch.Tensor, steps: torch.Tensor) -> torch.Tensor:
        """Teacher-forced NLL. targets/parents/branches (B, T); masks (B, T, V) allowed tokens;
        steps (B, T) True on real steps."""
        memory = self.encode(b)
        B = targets.shape[0]
        hs, toks = [memory["h0"]], [torch.full((B,), self.start_id, dtype=torch.long)]
        ctxs = [torch.zeros(B, self.out.in_features - self.cfg.hidden)]
        total = torch.zeros(())
        for t in range(targets.shape[1]):
            h, ctx, logits = self.run_step(memory, hs, ctxs, toks, parents[:, t], branches[:, t])
            hs.append(h)
            ctxs.append(ctx)
            toks.append(targets[:, t])
            logp = torch.log_softmax(logits.masked_fill(~masks[:, t], -1e9), -1)
            nll = -logp.gather(1, targets[:, t:t + 1]).squeeze(1)
            total = total + (nll * steps[:, t]).sum()
        return total / steps.sum()


class StackedEncoder:
    """The word encoders of an ensemble of flat-encoder networks with a word BiGRU, as one
    recurrence: every member's two directions are a group of one batched matrix product per
    word, where `nn.GRU` would run 2E recurrences of one small product each. Translating one
    description pays per-op overhead, not arithmetic, so for four members this halves the
    encoders' time (benchmarks/translator_speed.py times the stacked ensemble against member by
    member); it is `nn.GRU`'s arithmetic, to float rounding (tests), and gave the same trees on
    every fold of the default's saved networks."""

    def __init__(self, nets: list[Translator]) -> None:
        self.nets = nets
        grus = [n.word_gru for n in nets]
        # groups in the order (member 0 forward, member 0 backward, member 1 forward, ...)
        stack = lambda name: torch.stack([getattr(g, name + d).detach() for g in grus for d in ("", "_reverse")])
        self.w_ih, self.b_ih = stack("weight_ih_l0").transpose(1, 2), stack("bias_ih_l0")[:, None]
        self.w_hh, self.b_hh = stack("weight_hh_l0").transpose(1, 2), stack("bias_hh_l0")[:, None]

    def encode(self, b: Batch) -> list[dict]:
        """Every member's `Translator.encode(b)` (eval mode)."""
        x = torch.stack([net._inputs(b) for net in self.nets])  # (E, B, N, in)
        mask = b.words != 0
        states = self.bigru(x, b.lengths)
        return [net.flat_memory(states[e], mask) for e, net in enumerate(self.nets)]

    def bigru(self, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """x (E, B, N, in) -> (E, B, N, 2h): each member's BiGRU over each text's first
        `lengths` words, zeros after them (what `_bigru_packed` returns)."""
        E, B, N, _ = x.shape
        H = self.w_hh.shape[1]
        t = torch.arange(N)[None]
        lengths = lengths.clamp(min=1)[:, None]
        inside = t < lengths  # (B, N)
        # the backward direction reads each text from its own last word: reversed within its length
        rev = torch.where(inside, lengths - 1 - t, t)[None, :, :, None]
        x = torch.stack([x, x.gather(2, rev.expand_as(x))], 1).view(2 * E, B * N, -1)
        gi = torch.baddbmm(self.b_ih, x, self.w_ih).view(2 * E, B, N, 3 * H)  # every word's input part at once
        h, out = x.new_zeros(2 * E, B, H), []
        for s in range(N):
            g, gh = gi[:, :, s], torch.baddbmm(self.b_hh, h, self.w_hh)
            r, z = torch.sigmoid(g[..., :2 * H] + gh[..., :2 * H]).chunk(2, -1)  # reset, update, new
            h = torch.lerp(torch.tanh(g[..., 2 * H:] + r * gh[..., 2 * H:]), h, z)  # (1 - z) * new + z * h
            out.append(h)
        out = torch.stack(out, 2).view(E, 2, B, N, H)
        backward = out[:, 1].gather(2, rev.expand(E, B, N, H))
        return torch.cat([out[:, 0], backward], -1) * inside[None, :, :, None]


class StackedDecoder:
    """The decoder steps of an ensemble of flat-encoder networks, run as one batched computation.

    Same arithmetic as `Translator.step` in eval mode (dropout off), with every weight stacked on
    a leading member axis E, so a step costs a handful of batched matrix products instead of E
    rounds of small ones: translating one description is dominated by per-op overhead, and an
    ensemble of three would otherwise triple the decoder's share of the latency."""

    def __init__(self, nets: list[Translator]) -> None:
        stack = lambda get: torch.stack([get(n).detach() for n in nets])
        self.tok_emb, self.branch_emb = stack(lambda n: n.tok_emb.weight), stack(lambda n: n.branch_emb.weight)
        self.w_ih, self.b_ih = stack(lambda n: n.cell.weight_ih).transpose(1, 2), stack(lambda n: n.cell.bias_ih)[:, None]
        self.w_hh, self.b_hh = stack(lambda n: n.cell.weight_hh).transpose(1, 2), stack(lambda n: n.cell.bias_hh)[:, None]
        self.w_query = stack(lambda n: n.word_query.weight).transpose(1, 2)
        self.w_out, self.b_out = stack(lambda n: n.out.weight).transpose(1, 2), stack(lambda n: n.out.bias)[:, None]
        self.w_logits, self.b_logits = stack(lambda n: n.logits.weight).transpose(1, 2), stack(lambda n: n.logits.bias)[:, None]
        self.start_id = nets[0].start_id

    def step(self, words: torch.Tensor, mask: torch.Tensor, h_prev: torch.Tensor, ctx_prev: torch.Tensor,
             prev_tok: torch.Tensor, h_parent: torch.Tensor, parent_tok: torch.Tensor,
             branch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """words (E, B, N, mem), mask (B, N), states (E, B, .), tokens (B,). Returns (h, ctx,
        logits), each (E, B, .)."""
        inp = torch.cat([self.tok_emb[:, prev_tok], self.tok_emb[:, parent_tok], self.branch_emb[:, branch], h_parent, ctx_prev], -1)
        gi = torch.baddbmm(self.b_ih, inp, self.w_ih).chunk(3, -1)  # GRUCell: reset, update, new
        gh = torch.baddbmm(self.b_hh, h_prev, self.w_hh).chunk(3, -1)
        r, z = torch.sigmoid(gi[0] + gh[0]), torch.sigmoid(gi[1] + gh[1])
        h = (1 - z) * torch.tanh(gi[2] + r * gh[2]) + z * h_prev
        score = torch.einsum("ebnd,ebd->ebn", words, torch.bmm(h, self.w_query))
        att = torch.softmax(score.masked_fill(~mask, -1e9), -1)
        ctx = torch.einsum("ebn,ebnd->ebd", att, words)
        hidden = torch.tanh(torch.baddbmm(self.b_out, torch.cat([h, ctx], -1), self.w_out))
        return h, ctx, torch.baddbmm(self.b_logits, hidden, self.w_logits)


ARCHITECTURES: dict[tuple[str, str], type[Translator]] = {("flat", "tree"): Translator}
"""(encoder, decoder) of a ModelConfig -> its network class. The product ships flat + tree; the
lab adds the paper's other architectures (experiments/translation/baselines.py)."""


def build_network(cfg: ModelConfig, n_words: int, n_tree_tokens: int) -> Translator:
    """A fresh network for `cfg`; a clear error for an architecture this installation lacks."""
    try:
        cls = ARCHITECTURES[(cfg.encoder, cfg.decoder)]
    except KeyError:
        raise ValueError(f"no network for encoder {cfg.encoder!r} with decoder {cfg.decoder!r} "
                         f"(known: {sorted(ARCHITECTURES)}; the paper's baselines are in experiments/translation)") from None
    return cls(cfg, n_words, n_tree_tokens)
