"""Turning (description, tree) pairs into tensors, the training loop, and the trained translator.

`fit` is the whole training loop in plain view (Adam, teacher forcing, a few epochs), run
once per member of a small ensemble (members.py: their checkpoints, and worker processes to
train them side by side); `TrainedTranslator.predict` runs a beam search (decoding.py; greedy
with a beam of one) under the grammar mask with the members' probabilities averaged, so every
output is a valid tree, and returns each node's probability for the confidence score.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence, Union

import torch

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.language.grammar import allowed_tokens, next_slot
from nl2policy.language.decoding import beam_search, preorder_slots
from nl2policy.language.findings import FindingsModel
from nl2policy.language.members import MemberCheckpoints, train_forked
from nl2policy.language.models.config import ModelConfig
from nl2policy.language.models.network import Batch, Translator
from nl2policy.language.models.pathnet import decode_paths, tree_nodes
from nl2policy.language.models.pretrained import DIM as MINILM_DIM, MiniLMCache
from nl2policy.language.text import WordVocab, split_sentences
from nl2policy.trees import Tree, to_tokens

MAX_SENT_WORDS = 60
Pairs = Union[Sequence[tuple[str, Tree]], Callable[[int], Sequence[tuple[str, Tree]]]]
"""Training pairs: one list for every ensemble member, or member index -> that member's list."""


@dataclass
class Encoded:
    """One description ready for the network."""

    ids: list[int]
    sent_lengths: list[int]
    mini: Optional[torch.Tensor]


@dataclass
class TrainedTranslator:
    domain: str
    name: str
    cfg: ModelConfig
    words: WordVocab
    nets: list[Translator]  # an ensemble: decoding averages their step probabilities
    cache: MiniLMCache = field(default_factory=MiniLMCache, repr=False)
    history: list[float] = field(default_factory=list, repr=False)  # mean training loss per epoch
    beam: Optional[int] = None  # hypotheses kept while decoding (1 = greedy); None: the config's
    leaf_cost: Optional[float] = None  # decoding cost of an early leaf (see ModelConfig); None: the config's
    mention_cost: Optional[float] = None  # decoding cost of a named action the tree lacks (see ModelConfig); None: the config's
    question_cost: Optional[float] = None  # decoding cost of an asked question the tree lacks (see ModelConfig); None: the config's
    rule_cost: Optional[float] = None  # decoding cost of a stated rule the tree breaks (see ModelConfig); None: the config's
    root_cost: Optional[float] = None  # decoding cost of a root other than the stated first question; None: the config's
    findings_cost: Optional[float] = None  # weight of the learned findings in decoding (see ModelConfig); None: the config's
    findings: Optional["FindingsModel"] = field(default=None, repr=False)  # the learned findings (language/findings.py)
    ensemble: Optional[int] = None  # decode with the first n networks only; None: all of them
    stack_members: bool = True  # flat encoders: decode all members as one batch (False: one by one, same result)

    def decoding(self, setting: str) -> float:
        """A decoding cost (`leaf_cost`, `mention_cost`, ...): this translator's override, else its config's."""
        own = getattr(self, setting)
        return getattr(self.cfg, setting) if own is None else own

    @property
    def net(self) -> Translator:
        """The first network (the only one unless the config asks for an ensemble)."""
        return self.nets[0]

    @classmethod
    def from_states(cls, domain: str, name: str, cfg: ModelConfig, words: Sequence[str], states: Sequence[dict],
                    cache: MiniLMCache) -> TrainedTranslator:
        """A translator from saved networks: its word vocabulary (`words.itos[2:]`, as saved) and
        each network's state dict, in eval mode (a saved model file, a fold's kept networks)."""
        model = cls(domain, name, cfg, WordVocab(words), [], cache)
        for state in states:
            net = model.new_net()
            net.load_state_dict(state)
            model.nets.append(net.eval())
        return model

    def new_net(self) -> Translator:
        vocab = get_domain(self.domain).vocab
        return Translator(self.cfg, len(self.words), len(self.tree_tokens), len(vocab.question_ids))

    @property
    def label_domains(self) -> list[str]:
        """The domains whose labels the decoder scores: its own, then (with `cfg.other_domains`)
        the others, which only their own descriptions are trained on and the grammar never lets
        a decoding of this domain choose."""
        return [self.domain] + ([d for d in DOMAINS if d != self.domain] if self.cfg.other_domains else [])

    @property
    def tree_tokens(self) -> list[str]:
        """The labels the decoder scores: each of `label_domains`' questions, then its actions."""
        return [t for d in self.label_domains for t in get_domain(d).vocab.question_ids + get_domain(d).vocab.action_ids]

    def encode(self, text: str) -> Encoded:
        sentences = split_sentences(text) or [[]]
        sentences = [s[:MAX_SENT_WORDS] for s in sentences if s] or []
        flat = [t for s in sentences for t in s]
        mini = torch.from_numpy(self.cache.get(text, flat, self.cfg.minilm_layers)) if self.cfg.minilm and flat else None
        if self.cfg.minilm and mini is None:
            mini = torch.zeros(self.cfg.minilm_layers + 1, 0, MINILM_DIM, dtype=torch.float16)
        return Encoded(self.words.encode(t.text for t in flat), [len(s) for s in sentences], mini)

    @torch.inference_mode()
    def predict(self, texts: Sequence[str], batch_size: int = 64) -> list[tuple[Tree, dict[int, float]]]:
        """Grammar-constrained decoding (beam search, greedy when `beam` is 1). Returns (tree, {grid slot: probability})."""
        for net in self.nets:
            if net.training:  # eval() walks every submodule: a cost per call otherwise
                net.eval()
        out = []
        decode = self._decode_paths if self.cfg.decoder == "path" else self._decode
        for i in range(0, len(texts), batch_size):
            chunk = list(texts[i:i + batch_size])
            out += decode([self.encode(t) for t in chunk], chunk)
        return out

    def _decode_paths(self, items: list[Encoded], texts: list[str]) -> list[tuple[Tree, dict[int, float]]]:
        vocab = get_domain(self.domain).vocab
        memory = self.net.encode(collate(items))
        decoded = decode_paths(self.net.path, memory["words"], memory["mask"], self.tree_tokens, len(vocab.question_ids))
        return [(tree, dict(zip(preorder_slots(tree), probs))) for tree, probs in decoded]

    def _decode(self, items: list[Encoded], texts: list[str]) -> list[tuple[Tree, dict[int, float]]]:
        return beam_search(self, collate(items), texts)


def path_loss(net: Translator, batch: Batch, nodes: list[list[tuple[tuple, int]]], n_labels: int) -> torch.Tensor:
    """Mean cross-entropy over every node of every tree in the batch (path decoder)."""
    memory = net.encode(batch)
    doc = [b for b, ns in enumerate(nodes) for _ in ns]
    flat = [n for ns in nodes for n in ns]
    node_batch = net.path.node_batch(doc, [p for p, _ in flat], n_labels)
    logits = net.path(memory["words"], memory["mask"], node_batch)
    return torch.nn.functional.cross_entropy(logits, torch.tensor([y for _, y in flat]))


def collate(items: Sequence[Encoded]) -> Batch:
    B = len(items)
    N = max(1, max(len(e.ids) for e in items))
    S = max(1, max(len(e.sent_lengths) for e in items))
    W = max([1] + [l for e in items for l in e.sent_lengths])
    words = torch.zeros(B, N, dtype=torch.long)
    sent_index = torch.full((B, S, W), N, dtype=torch.long)
    sent_lengths = torch.zeros(B, S, dtype=torch.long)
    sent_ids = torch.zeros(B, N, dtype=torch.long)
    for b, e in enumerate(items):
        words[b, : len(e.ids)] = torch.tensor(e.ids, dtype=torch.long)
        pos = 0
        for s, n in enumerate(e.sent_lengths):
            sent_index[b, s, :n] = torch.arange(pos, pos + n)
            sent_lengths[b, s] = n
            sent_ids[b, pos:pos + n] = s
            pos += n
    minis = None
    if items[0].mini is not None:
        minis = torch.zeros(B, items[0].mini.shape[0], N, items[0].mini.shape[2])
        for b, e in enumerate(items):
            minis[b, :, : e.mini.shape[1]] = e.mini.float()
    return Batch(words, torch.tensor([max(1, len(e.ids)) for e in items]), minis, sent_index, sent_lengths, sent_ids,
                 torch.tensor([max(1, len(e.sent_lengths)) for e in items]))


def tree_domain(tree: Tree, domains: Sequence[str]) -> str:
    """Which of `domains` a tree's labels come from (their question and action ids are disjoint)."""
    first = to_tokens(tree)[0]
    for d in domains:
        vocab = get_domain(d).vocab
        if first in vocab.questions or first in vocab.actions:
            return d
    raise ValueError(f"{first!r} is a label of none of {', '.join(domains)}")


def gold_steps(tree: Tree, domain: str, names: list[str]) -> tuple[list[int], list[int], list[int], list[list[bool]]]:
    """Targets, parent positions, branches and allowed-token masks along a gold tree of `domain`
    (the masks allow that domain's tokens only, whichever labels `names` holds)."""
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
    if cfg.other_domains and cfg.decoder == "path":
        raise ValueError("other_domains needs a decoder that reads its labels from tree_tokens (tree or seq)")
    model = TrainedTranslator(domain, name, cfg, words, [], cache or MiniLMCache())
    names, domains = model.tree_tokens, model.label_domains
    ckpt = MemberCheckpoints(state, on_epoch)
    last_pairs, encoded, golds = None, [], []  # the pairs last encoded: members sharing one list encode it once

    def train_member(member: int, report: Optional[Callable[[int, int], None]], save: Callable[[dict], None]) -> tuple[dict, list[float]]:
        nonlocal last_pairs, encoded, golds
        torch.manual_seed(seed + cfg.seed_offset + member)  # the initial weights: a member is reproducible from its seed
        net = model.new_net()
        member_pairs = draw(member)
        if member_pairs is not last_pairs:
            if cfg.decoder == "path":
                golds = [tree_nodes(tree, names, vocab.question_ids) for _, tree in member_pairs]
            else:
                golds = [gold_steps(tree, tree_domain(tree, domains), names) for _, tree in member_pairs]
            last_pairs, encoded = member_pairs, [model.encode(t) for t, _ in member_pairs]
        history = _fit_member(model, net, encoded, golds, len(names), seed + cfg.seed_offset + member, ckpt.partial.get(member), save, report)
        return net.state_dict(), history

    todo = [m for m in range(cfg.ensemble) if m not in ckpt.finished]
    done = [0] * cfg.ensemble  # updates so far by each member trained in this call

    def report(member: int, n: int, of: int) -> None:
        done[member] = n
        if progress:
            progress(sum(done) + of * (cfg.ensemble - len(todo)), of * cfg.ensemble)

    if workers > 1 and len(todo) > 1:
        if vocab_texts is not None:  # encode the shared real descriptions once, before the fork
            for text in vocab_texts:
                model.encode(text)
        train_forked(todo, train_member, workers, report, ckpt)
    else:
        for member in todo:
            ckpt.finish(member, *train_member(member, lambda n, of, m=member: report(m, n, of),
                                               lambda c, m=member: ckpt.save(m, c)))
    for member in range(cfg.ensemble):
        net = model.new_net()
        net.load_state_dict(ckpt.finished[member])
        model.nets.append(net.eval())
        model.history += ckpt.history[member]
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
    tuned = list(net.mini_top.parameters()) if cfg.minilm_tune else []
    tuned_ids = {id(p) for p in tuned}
    groups = [{"params": [p for p in net.parameters() if id(p) not in tuned_ids], "lr": cfg.lr}]
    if tuned:  # pretrained layers: their own, smaller rate
        groups.append({"params": tuned, "lr": cfg.minilm_lr})
    peaks = [group["lr"] for group in groups]
    opt = torch.optim.Adam(groups)
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
            if cfg.decoder == "path":
                loss = path_loss(net, batch, [golds[i] for i in idx], n_names)
            else:
                loss = net.loss(batch, *_targets([golds[i] for i in idx], n_names))
            for group, peak in zip(opt.param_groups, peaks):
                group["lr"] = _cosine_lr(peak, epoch * n_batches + k, cfg.epochs * n_batches)
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
