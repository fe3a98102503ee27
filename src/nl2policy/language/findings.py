"""What a description says about its tree, learned: which questions it asks, which actions it
takes, which question comes first.

A second reader of the text beside the translator. The translator writes a tree node by node,
and where the text describes a tree it never saw, it falls back on the trees it knows: a subtree
collapsed into one action, a question dropped, the habitual root. These findings are per label
(one yes/no per question, one per action, one choice of root), so they compose: a classifier
that learned "asks at_city" from a few hundred texts reads it in a tree it never saw. The
decoder's final choice among its beam's trees weighs each tree by how well it agrees with them,
and the root's probability is added at the first step, so the beam explores trees under the root
the text asks first (decoding.beam_search). The same findings explain the warnings of
`translate` (an action the text seems to take, a question it seems to ask, that the tree leaves out).

Nothing here was written by reading descriptions: the network is label-wise attention over frozen
MiniLM states (one learned query per label, as in label-attention text classifiers), trained on
the translator's own training pairs, and the weights it adds to the decoder's scores are
log-probabilities (one nat is one nat), not tuned.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Optional, Sequence

import torch
from torch import nn

from nl2policy.domains import get_domain
from nl2policy.language.models.network import _bigru_packed
from nl2policy.language.models.pretrained import DIM, MiniLMCache
from nl2policy.language.text import Token, split_sentences
from nl2policy.trees import Tree
from nl2policy.trees.tree import iter_leaves, questions_used

LAYERS = 6
"""MiniLM layers read (the translator's networks read the same six, so the cache serves both)."""


@dataclass(frozen=True)
class FindingsConfig:
    hidden: int = 128
    dropout: float = 0.3
    epochs: int = 25
    lr: float = 3e-3
    batch: int = 32


def text_tokens(text: str, max_sent_words: int = 60) -> list[Token]:
    """The text's tokens as the translator reads them (sentences cut at `max_sent_words`)."""
    return [t for s in split_sentences(text) for t in s[:max_sent_words]]


class FindingsNet(nn.Module):
    """MiniLM layers (mixed) -> BiGRU -> one attention query per label -> one logit per label.

    Labels: each question ("does the tree ask it?"), each action ("does a leaf take it?"), and
    the root, a choice among every question and action (a one-leaf tree's root is its action).
    (Rules as labels, (question, answer, action) for every leaf and condition on its path, were
    tried on one leave-trees-out fold and decoded worse at every weight: results/translation/history/findings/.)"""

    def __init__(self, n_questions: int, n_actions: int, cfg: FindingsConfig = FindingsConfig()) -> None:
        super().__init__()
        self.n_questions, self.n_actions = n_questions, n_actions
        h = cfg.hidden
        self.mix = nn.Parameter(torch.zeros(LAYERS + 1))
        self.norm = nn.LayerNorm(DIM)
        self.rnn = nn.GRU(DIM, h // 2, batch_first=True, bidirectional=True)
        self.drop = nn.Dropout(cfg.dropout)
        labels = n_questions + n_actions
        self.queries = nn.Parameter(torch.randn(labels + 1, h) / math.sqrt(h))  # the last one reads the root
        self.label_out = nn.Parameter(torch.randn(labels, h) / math.sqrt(h))
        self.label_bias = nn.Parameter(torch.zeros(labels))
        self.root_out = nn.Linear(h, labels)

    def forward(self, states: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """states (B, L+1, N, 384), mask (B, N) -> (label logits (B, Q+A), root logits (B, Q+A))."""
        x = torch.einsum("l,blnd->bnd", torch.softmax(self.mix, 0), states)
        # packed: a text's reading must not depend on the longer texts beside it in a batch (the
        # backward direction would start in their padding), so a batch reads as one text alone does
        x = _bigru_packed(self.rnn, self.drop(self.norm(x)), mask.sum(1))
        x = self.drop(x)
        att = torch.einsum("bnh,kh->bkn", x, self.queries).masked_fill(~mask[:, None, :], -1e9)
        pooled = torch.einsum("bkn,bnh->bkh", torch.softmax(att, -1), x)  # (B, labels+1, h)
        labels = (pooled[:, :-1] * self.label_out).sum(-1) + self.label_bias
        return labels, self.root_out(pooled[:, -1])


@dataclass
class Findings:
    """One text's findings: the probability that the tree asks each question and takes each
    action, and the probability of each label at the root."""

    asks: dict[str, float]
    takes: dict[str, float]
    root: dict[str, float]

    def log_agreement(self, tree: Tree) -> float:
        """log P(the tree's question set, action set and root) under the findings: how well a tree
        agrees with what the text was read to say (the decoder adds the same, part by part, as
        its hypotheses grow)."""
        asked = questions_used(tree)
        taken = {leaf.action for leaf in iter_leaves(tree)}
        total = sum(math.log(max(p if q in asked else 1 - p, 1e-6)) for q, p in self.asks.items())
        total += sum(math.log(max(p if a in taken else 1 - p, 1e-6)) for a, p in self.takes.items())
        return total + math.log(max(self.root[root_label(tree)], 1e-6))


def root_label(tree: Tree) -> str:
    """The label at a tree's root: its question, or a one-leaf tree's action."""
    return getattr(tree, "question", None) or tree.action


class FindingsModel:
    """A trained FindingsNet for one domain, with the MiniLM cache it reads."""

    def __init__(self, domain: str, net: FindingsNet, cache: Optional[MiniLMCache] = None) -> None:
        vocab = get_domain(domain).vocab
        self.domain, self.net = domain, net.eval()
        self.questions, self.actions = list(vocab.question_ids), list(vocab.action_ids)
        self.cache = cache or MiniLMCache(max_items=256)

    @property
    def labels(self) -> list[str]:
        return self.questions + self.actions

    def state(self) -> dict:
        return {"domain": self.domain, "net": self.net.state_dict(), "hidden": self.net.queries.shape[1]}

    @classmethod
    def from_state(cls, state: dict, cache: Optional[MiniLMCache] = None) -> FindingsModel:
        vocab = get_domain(state["domain"]).vocab
        net = FindingsNet(len(vocab.question_ids), len(vocab.action_ids), FindingsConfig(hidden=state["hidden"]))
        net.load_state_dict(state["net"])
        return cls(state["domain"], net, cache)

    @torch.inference_mode()
    def read(self, texts: Sequence[str]) -> list[Findings]:
        states, mask = _batch(texts, self.cache)
        logits, root = self.net(states, mask)
        p, root_p = torch.sigmoid(logits), torch.softmax(root, -1)
        nq, labels = len(self.questions), self.labels
        return [Findings({q: float(p[b, i]) for i, q in enumerate(self.questions)},
                         {a: float(p[b, nq + i]) for i, a in enumerate(self.actions)},
                         {l: float(root_p[b, i]) for i, l in enumerate(labels)}) for b in range(len(texts))]


def _batch(texts: Sequence[str], cache: MiniLMCache) -> tuple[torch.Tensor, torch.Tensor]:
    arrays = []
    for text in texts:
        tokens = text_tokens(text)
        arrays.append(torch.from_numpy(cache.get(text, tokens, LAYERS)).float() if tokens
                      else torch.zeros(LAYERS + 1, 1, DIM))
    n = max(a.shape[1] for a in arrays)
    states = torch.zeros(len(arrays), LAYERS + 1, n, DIM)
    mask = torch.zeros(len(arrays), n, dtype=torch.bool)
    for b, a in enumerate(arrays):
        states[b, :, :a.shape[1]] = a
        mask[b, :max(1, a.shape[1])] = True
    return states, mask


def train_findings(domain: str, pairs: Sequence[tuple[str, Tree]], seed: int = 0,
                   cache: Optional[MiniLMCache] = None, cfg: FindingsConfig = FindingsConfig()) -> FindingsModel:
    """Train the findings on (description, tree) pairs: binary cross-entropy per question and
    action, cross-entropy for the root; Adam with a cosine schedule, as the translator trains."""
    cache = cache or MiniLMCache()
    vocab = get_domain(domain).vocab
    questions, actions = list(vocab.question_ids), list(vocab.action_ids)
    labels = questions + actions
    index = {l: i for i, l in enumerate(labels)}
    targets = torch.zeros(len(pairs), len(labels))
    roots = torch.zeros(len(pairs), dtype=torch.long)
    for k, (_, tree) in enumerate(pairs):
        for q in questions_used(tree):
            targets[k, index[q]] = 1.0
        for leaf in iter_leaves(tree):
            targets[k, index[leaf.action]] = 1.0
        roots[k] = index[root_label(tree)]
    torch.manual_seed(seed)
    rng = random.Random(seed)
    net = FindingsNet(len(questions), len(actions), cfg)
    texts = [t for t, _ in pairs]
    for t in texts:  # fill the cache once, before the epochs
        _batch([t], cache)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    order = list(range(len(pairs)))
    steps = cfg.epochs * math.ceil(len(order) / cfg.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=steps, pct_start=0.1)
    bce, ce = nn.BCEWithLogitsLoss(), nn.CrossEntropyLoss()
    net.train()
    for _ in range(cfg.epochs):
        rng.shuffle(order)
        for i in range(0, len(order), cfg.batch):
            idx = order[i:i + cfg.batch]
            states, mask = _batch([texts[j] for j in idx], cache)
            logits, root = net(states, mask)
            loss = bce(logits, targets[idx]) + ce(root, roots[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
    return FindingsModel(domain, net, cache)
