"""Probe: noisy-channel reranking of the translator's beam (Yu et al., "The Neural Noisy Channel",
ICLR 2017; Yee et al., "Simple and Effective Noisy Channel Modeling for Neural Machine
Translation", EMNLP 2019).

On kept NWNT networks the gold tree is in a 16-wide beam far more often than it is first (taxi
v5: 113 of 120 against 94), and most deep-tree misses are a smaller or branch-swapped tree. A
channel model P(text | tree) must account for every word of the description, so a tree that
leaves out a question the text asks, or swaps which branch an action sits on, should explain the
text worse. Each candidate is scored by log P(tree | text) (the translator's own beam score) plus
log P(text | tree) (this model), weight 1 each (fixed before any run).

    .venv/bin/python -m experiments.translation.channel --networks /work/scratch/nets_v5 --name v5 \\
        --model v5-mean --out results/translation/history/channel

The channel model: each of the tree's 15 grid slots is its token's embedding plus the slot's; a
GRU language model over the description's words attends to the slots. It trains on the fold's
own training pairs (member 0's draw), so it never sees the held-out writer or trees.
"""

from __future__ import annotations

import json
import math
import random
import time
from collections import Counter
from pathlib import Path
from typing import Optional, Sequence

import torch
import torch.nn as nn
import typer

import experiments.translation.baselines  # noqa: F401  (registers the lab's models)
from experiments.translation.evaluate import plan_folds
from nl2policy.language.corpus import policy_key
from nl2policy.language.corpus import load_corpus  # noqa: E402
from nl2policy.language.dataset import member_pairs
from nl2policy.language.decoding import search
from nl2policy.language.models.config import MODELS
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.text import tokenize
from nl2policy.language.translator import TrainedTranslator, collate
from nl2policy.trees import to_tokens
from nl2policy.trees.grid import to_grid
from nl2policy.trees.tree import GRID_SLOTS, Leaf, Tree

MAX_WORDS = 160
"""Words of a description the channel model reads (longer ones are cut; the same cut for every candidate)."""


class Channel(nn.Module):
    """P(words | tree): a GRU language model attending to the tree's 15 grid slots."""

    def __init__(self, n_words: int, n_tree: int, hidden: int = 128, embed: int = 64, dropout: float = 0.2) -> None:
        super().__init__()
        self.tree_emb = nn.Embedding(n_tree + 1, hidden, padding_idx=0)
        self.slot_emb = nn.Embedding(GRID_SLOTS, hidden)
        self.word_emb = nn.Embedding(n_words, embed, padding_idx=0)
        self.init = nn.Linear(hidden, hidden)
        self.gru = nn.GRU(embed + hidden, hidden, batch_first=True)
        self.query = nn.Linear(hidden, hidden, bias=False)
        self.out = nn.Linear(2 * hidden, n_words)
        self.drop = nn.Dropout(dropout)

    def forward(self, slots: torch.Tensor, words: torch.Tensor) -> torch.Tensor:
        """slots (B, 15) tree-token ids (0 = empty), words (B, T) with BOS first: logits (B, T, V)."""
        mem = self.tree_emb(slots) + self.slot_emb.weight[None]
        mask = slots != 0
        summary = (mem * mask[..., None]).sum(1) / mask.sum(1, keepdim=True).clamp(min=1)
        x = self.drop(self.word_emb(words))
        # one GRU pass over the words (with the tree's summary at every step), then each step attends to the slots
        o, _ = self.gru(torch.cat([x, summary[:, None].expand(-1, x.shape[1], -1)], -1),
                        torch.tanh(self.init(summary))[None].contiguous())
        att = torch.softmax(torch.einsum("bsd,btd->bts", mem, self.query(o)).masked_fill(~mask[:, None], -1e9), -1)
        ctx = torch.einsum("bts,bsd->btd", att, mem)
        return self.out(self.drop(torch.cat([o, ctx], -1)))


class ChannelScorer:
    """A trained channel model with its vocabularies: `logp(text, trees)` per tree."""

    def __init__(self, pairs: Sequence[tuple[str, Tree]], tree_tokens: Sequence[str], seed: int = 0,
                 epochs: int = 12, batch: int = 32, lr: float = 3e-3) -> None:
        torch.manual_seed(seed)
        counts = Counter(w for text, _ in pairs for w in tokenize(text)[:MAX_WORDS])
        self.itos = ["<pad>", "<unk>", "<bos>", "<eos>"] + sorted(w for w, c in counts.items() if c >= 2)
        self.stoi = {w: i for i, w in enumerate(self.itos)}
        self.tree_index = {t: i + 1 for i, t in enumerate(tree_tokens)}
        self.net = Channel(len(self.itos), len(tree_tokens))
        opt = torch.optim.Adam(self.net.parameters(), lr=lr)
        data = [(self._slots(tree), self._words(text)) for text, tree in pairs]
        rng = random.Random(seed)
        steps = epochs * math.ceil(len(data) / batch)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
        self.losses = []
        self.net.train()
        for _ in range(epochs):
            order = sorted(range(len(data)), key=lambda i: (len(data[i][1]), rng.random()))  # length buckets
            chunks = [order[i:i + batch] for i in range(0, len(order), batch)]
            rng.shuffle(chunks)
            total, n = 0.0, 0
            for chunk in chunks:
                loss = self._nll([data[i] for i in chunk]).mean()
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(self.net.parameters(), 1.0)
                opt.step()
                sched.step()
                total, n = total + loss.item(), n + 1
            self.losses.append(total / n)
        self.net.eval()

    def _slots(self, tree: Tree) -> list[int]:
        return [0 if t is None else self.tree_index[t] for t in to_grid(tree)]

    def _words(self, text: str) -> list[int]:
        return [self.stoi.get(w, 1) for w in tokenize(text)[:MAX_WORDS]] + [3]

    def _nll(self, items: Sequence[tuple[list[int], list[int]]]) -> torch.Tensor:
        """Each item's summed negative log-likelihood of its words (and EOS)."""
        T = max(len(w) for _, w in items)
        slots = torch.tensor([s for s, _ in items])
        target = torch.tensor([w + [0] * (T - len(w)) for _, w in items])
        inputs = torch.cat([torch.full((len(items), 1), 2), target[:, :-1]], 1)
        logits = self.net(slots, inputs)
        nll = nn.functional.cross_entropy(logits.transpose(1, 2), target, ignore_index=0, reduction="none")
        return nll.sum(1) / (target != 0).sum(1).clamp(min=1) if self.net.training else nll.sum(1)

    def logp(self, text: str, trees: Sequence[Tree]) -> list[float]:
        words = self._words(text)
        with torch.inference_mode():
            return [-float(x) for x in self._nll([(self._slots(t), words) for t in trees])]


def _questions(tree: Tree) -> int:
    return 0 if isinstance(tree, Leaf) else 1 + _questions(tree.yes) + _questions(tree.no)


def main(networks: Path = typer.Option(..., help="A --keep-networks folder of NWNT folds"),
         name: str = typer.Option(..., help="The model name in the kept files' names (DOMAIN-NAME-FOLD.pt)"),
         model: str = typer.Option(..., help="The registered model to decode them as (its beam, length_norm)"),
         domain: str = typer.Option("taxi"), width: int = typer.Option(16, help="Beam width of the candidates"),
         epochs: int = typer.Option(12), out: Path = typer.Option(Path("results/translation/history/channel")),
         fold: list[str] = typer.Option([], help="Only these folds (default: every kept one)")) -> None:
    """Rerank each NWNT fold's beam by log P(tree | text) + log P(text | tree); write OUT/NAME.jsonl."""
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    cfg = MODELS[model]
    specs = load_corpus(domain, rounds=(1, 2))
    cache = MiniLMCache()
    path = out / f"{domain}-{model}.jsonl"
    done = {json.loads(l)["fold"] for l in path.read_text().splitlines()} if path.is_file() else set()
    command = (f"python -m experiments.translation.channel --networks {networks} --name {name} --model {model} "
               f"--domain {domain} --width {width} --epochs {epochs} --out {out}")
    for key, tr, te in plan_folds(specs, "new", 1):
        kept = networks / f"{domain}-{name}-{key}.pt"
        if key in done or not kept.is_file() or (fold and key not in fold):
            continue
        start = time.time()
        saved = torch.load(kept, weights_only=False)
        assert saved["train"] == list(tr) and saved["test"] == list(te), f"{kept} is another fold"
        translator = TrainedTranslator.from_states(domain, model, cfg, saved["words"], saved["nets"][:cfg.ensemble], cache)
        held = {policy_key(domain, specs[i].tree) for i in te}
        pairs = member_pairs(domain, specs, tr, cfg, exclude=lambda t: policy_key(domain, t) in held)
        pairs = pairs(0) if callable(pairs) else pairs
        channel = ChannelScorer(pairs, translator.tree_tokens, seed=0, epochs=epochs)
        texts = [specs[i].description for i in te]
        with torch.inference_mode():
            beams = search(translator, collate([translator.encode(t) for t in texts]), texts, width=width)
        rows = []
        for i, text, hyps in zip(te, texts, beams):
            trees = [t for t, _, _ in hyps]
            direct = [s for _, _, s in hyps]
            chan = channel.logp(text, trees)
            gold = specs[i].tree
            rank = lambda scores: trees[max(range(len(trees)), key=lambda j: scores[j])]
            rows.append({"id": specs[i].id, "questions": _questions(gold), "gold_in_beam": gold in trees,
                         "beam_top": rank([d / (len(to_tokens(t)) ** cfg.length_norm if cfg.length_norm else 1)
                                           for d, t in zip(direct, trees)]) == gold,
                         "channel_only": rank(chan) == gold,
                         "direct_plus_channel": rank([d + c for d, c in zip(direct, chan)]) == gold})
        record = {"fold": key, "model": model, "networks": str(kept), "width": width, "epochs": epochs,
                  "channel_losses": [round(x, 4) for x in channel.losses], "train_pairs": len(pairs),
                  "seconds": round(time.time() - start, 1), "command": command, "rows": rows}
        with path.open("a") as fh:
            fh.write(json.dumps(record) + "\n")
        n = len(rows)
        print(f"{key}: beam top {sum(r['beam_top'] for r in rows)}/{n}, channel only {sum(r['channel_only'] for r in rows)}/{n}, "
              f"direct + channel {sum(r['direct_plus_channel'] for r in rows)}/{n}, gold in beam {sum(r['gold_in_beam'] for r in rows)}/{n}, "
              f"losses {record['channel_losses'][0]:.2f} -> {record['channel_losses'][-1]:.2f}, {record['seconds']:.0f} s", flush=True)


if __name__ == "__main__":
    typer.run(main)
