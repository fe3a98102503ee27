"""Turning (description, tree) pairs into tensors and the training loop.

`fit` is the whole training loop in plain view (Adam, teacher forcing, a few epochs), run
once per member of a small ensemble (members.py: their checkpoints, and worker processes to
train them side by side); `TrainedTranslator.predict` runs a beam search (decoding.py; greedy
with a beam of one) under the grammar mask with the members' probabilities averaged, so every
output is a valid tree, and returns each node's probability for the confidence score.
"""

from __future__ import annotations

import math
import random
from typing import Callable, Optional, Sequence, Union

import torch

from nl2policy.domains import get_domain
from nl2policy.language.findings import FindingsModel, train_findings
from nl2policy.language.grammar import allowed_tokens, next_slot
from nl2policy.language.members import MemberCheckpoints, train_forked
from nl2policy.language.models.config import ModelConfig
from nl2policy.language.models.network import Translator
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.text import WordVocab
from nl2policy.language.translator import Encoded, TrainedTranslator, collate
from nl2policy.trees import Tree, to_tokens

Pairs = Union[Sequence[tuple[str, Tree]], Callable[[int], Sequence[tuple[str, Tree]]]]
"""Training pairs: one list for every ensemble member, or member index -> that member's list."""


def gold_steps(tree: Tree, domain: str, names: list[str]) -> tuple[list[int], list[int], list[int], list[list[bool]]]:
    """Targets, parent positions, branches and allowed-token masks along a gold tree of `domain`."""
    vocab = get_domain(domain).vocab
    tokens = to_tokens(tree)
    targets, parents, branches, masks = [], [], [], []
    for t, tok in enumerate(tokens):
        slot = next_slot(tokens[:t], vocab)
        allowed = set(allowed_tokens(slot, vocab))
        targets.append(names.index(tok))
        parents.append(slot.parent)
        branches.append(slot.branch)
        masks.append([n in allowed for n in names])
    return targets, parents, branches, masks


def _targets(golds: list, n_names: int) -> tuple[torch.Tensor, ...]:
    B, T = len(golds), max(len(g[0]) for g in golds)
    targets = torch.zeros(B, T, dtype=torch.long)
    parents = torch.full((B, T), -1, dtype=torch.long)
    branches = torch.zeros(B, T, dtype=torch.long)
    masks = torch.ones(B, T, n_names, dtype=torch.bool)
    steps = torch.zeros(B, T)
    for b, (tg, pa, br, mk) in enumerate(golds):
        n = len(tg)
        targets[b, :n], parents[b, :n], branches[b, :n] = torch.tensor(tg), torch.tensor(pa), torch.tensor(br)
        masks[b, :n] = torch.tensor(mk)
        steps[b, :n] = 1
    return targets, parents, branches, masks, steps


def fit(domain: str, name: str, cfg: ModelConfig, pairs: Pairs, seed: int = 0,
        cache: Optional[MiniLMCache] = None, progress: Optional[Callable[[int, int], None]] = None,
        vocab_texts: Optional[Sequence[str]] = None, state: Optional[dict] = None,
        on_epoch: Optional[Callable[[dict], None]] = None, workers: int = 1) -> TrainedTranslator:
    """Train a translator on (description, tree) pairs: `cfg.ensemble` networks with seeds seed,
    seed+1, ... (each plus `cfg.seed_offset`). `pairs` is one list for every member, or a function of the member index that
    gives each member its own draw (of augmented and synthetic pairs). The word vocabulary comes
    from `vocab_texts` (the real training descriptions) or the first member's pairs.

    A member depends only on its seed and its draw, so with `workers` > 1 the members train in
    that many forked processes of one CPU thread each, into the same networks as one thread
    training them one by one. It takes ceil(members / workers) rounds instead of one per
    member: three members on two cores train 1.16x faster than one by one on two threads
    (benchmarks/translator_speed.py; the third round leaves a core idle), four in the same time.

    After every epoch of any member, `on_epoch` gets a checkpoint dict (see `members.MemberCheckpoints`);
    passing one back as `state` resumes there."""
    draw = pairs if callable(pairs) else (lambda member: pairs)
    words = WordVocab.build(vocab_texts if vocab_texts is not None else [t for t, _ in draw(0)])
    vocab = get_domain(domain).vocab
    model = TrainedTranslator(domain, name, cfg, words, [], cache or MiniLMCache())
    names = model.tree_tokens
    ckpt = MemberCheckpoints(state, on_epoch)
    last_pairs, encoded, golds = None, [], []  # the pairs last encoded: members sharing one list encode it once

    def train_member(member: int, report: Optional[Callable[[int, int], None]], save: Callable[[dict], None]) -> tuple[dict, list[float]]:
        nonlocal last_pairs, encoded, golds
        torch.manual_seed(seed + cfg.seed_offset + member)  # the initial weights: a member is reproducible from its seed
        net = model.new_net()
        member_pairs = draw(member)
        if member_pairs is not last_pairs:
            golds = [gold_steps(tree, domain, names) for _, tree in member_pairs]
            last_pairs, encoded = member_pairs, [model.encode(t) for t, _ in member_pairs]
        history = _fit_member(model, net, encoded, golds, len(names), seed + cfg.seed_offset + member, ckpt.partial.get(member), save, report)
        return net.state_dict(), history

    todo = [m for m in range(cfg.ensemble) if m not in ckpt.finished]
    done = [0] * cfg.ensemble  # updates so far by each member trained in this call

    def report(member: int, n: int, of: int) -> None:
        done[member] = n
        if progress:
            progress(sum(done) + of * (cfg.ensemble - len(todo)), of * cfg.ensemble)

    findings_seed = seed + cfg.seed_offset
    wants_findings = cfg.findings or bool(cfg.findings_cost)  # weighed in decoding, or read by the warnings alone
    if workers > 1 and len(todo) > 1:
        if vocab_texts is not None:  # encode the shared real descriptions once, before the fork
            for text in vocab_texts:
                model.encode(text)
        side = (lambda: train_findings(domain, draw(0), findings_seed, model.cache).state()) if wants_findings else None
        findings_state = train_forked(todo, train_member, workers, report, ckpt, side_job=side)
        if findings_state is not None:  # the same findings as trained below, one thread either way
            model.findings = FindingsModel.from_state(findings_state, model.cache)
    else:
        for member in todo:
            ckpt.finish(member, *train_member(member, lambda n, of, m=member: report(m, n, of),
                                               lambda c, m=member: ckpt.save(m, c)))
    for member in range(cfg.ensemble):
        net = model.new_net()
        net.load_state_dict(ckpt.finished[member])
        model.nets.append(net.eval())
        model.history += ckpt.history[member]
    if wants_findings and model.findings is None:  # the learned findings (findings.py), on the first member's pairs
        model.findings = train_findings(domain, draw(0), findings_seed, model.cache)
    return model


def _fit_member(model: "TrainedTranslator", net: Translator, encoded: list[Encoded], golds: list, n_names: int, seed: int,
                state: Optional[dict], checkpoint: Callable[[dict], None],
                progress: Optional[Callable[[int, int], None]]) -> list[float]:
    """The training loop of one network: Adam, teacher forcing, cosine learning rate, batches
    of descriptions of similar length (padding is most of the cost otherwise). Returns the
    mean training loss of each epoch; `checkpoint` gets the network, optimizer and random
    states after each."""
    cfg = model.cfg
    rng = random.Random(seed)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    start_epoch, history = 0, []
    if state is not None:
        net.load_state_dict(state["net"])
        opt.load_state_dict(state["opt"])
        start_epoch, history = state["epoch"], list(state["history"])
        rng.setstate(state["rng"])
        torch.set_rng_state(state["torch_rng"])  # dropout masks continue as if never stopped
    n_batches = (len(encoded) + cfg.batch - 1) // cfg.batch
    lengths = [len(e.ids) for e in encoded]
    for epoch in range(start_epoch, cfg.epochs):
        net.train()
        losses = []
        for k, idx in enumerate(_length_batches(lengths, cfg.batch, rng)):
            batch = collate([_word_dropout(encoded[i], rng) for i in idx])
            loss = net.loss(batch, *_targets([golds[i] for i in idx], n_names))
            for group in opt.param_groups:
                group["lr"] = _cosine_lr(cfg.lr, epoch * n_batches + k, cfg.epochs * n_batches)
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 5.0)
            opt.step()
            losses.append(loss.item())
            if progress:
                progress(epoch * n_batches + k + 1, cfg.epochs * n_batches)
        history.append(sum(losses) / len(losses))
        checkpoint({"epoch": epoch + 1, "history": list(history), "net": net.state_dict(), "opt": opt.state_dict(),
                    "rng": rng.getstate(), "torch_rng": torch.get_rng_state()})
    return history


def _length_batches(lengths: Sequence[int], size: int, rng: random.Random, pool: int = 8) -> list[list[int]]:
    """Shuffled batches whose members have similar lengths: shuffle, sort within pools of
    `pool` batches, cut, shuffle the batches. A code snippet padded to an explainer's 250
    words costs as much as the explainer; this keeps most batches tight."""
    order = list(range(len(lengths)))
    rng.shuffle(order)
    batches = []
    for p in range(0, len(order), size * pool):
        chunk = sorted(order[p:p + size * pool], key=lambda i: lengths[i])
        batches += [chunk[i:i + size] for i in range(0, len(chunk), size)]
    rng.shuffle(batches)
    return batches


def _cosine_lr(base: float, step: int, total: int, floor: float = 0.05) -> float:
    """Cosine decay from `base` to `floor * base`: with a few hundred updates on a few hundred
    pairs, a constant rate leaves the last epochs jumping between solutions (test accuracy
    swung 75 -> 55% between epochs 20 and 30 on one fold); decaying settles the model."""
    return base * (floor + (1 - floor) * 0.5 * (1 + math.cos(math.pi * min(step, total) / max(1, total))))


def _word_dropout(e: Encoded, rng: random.Random, p: float = 0.1) -> Encoded:
    """Replace a few word ids by <unk> so the model also reads the unknown words of new writers."""
    return Encoded([1 if rng.random() < p else i for i in e.ids], e.sent_lengths, e.mini)
