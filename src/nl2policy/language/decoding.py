"""Grammar-constrained decoding of a trained translator: the beam search over the ensemble's
averaged step probabilities, weighed by the text's learned findings (findings.py), and the
running decoder state it reorders.

Every step is masked by the grammar (grammar.py), so every output is a valid tree of the domain;
each node's probability comes back with the tree, for the confidence score.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable, Optional, Sequence

import torch

from nl2policy.domains import get_domain
from nl2policy.language.grammar import Slot, allowed_tokens, next_slot
from nl2policy.language.models.network import Batch, StackedDecoder, StackedEncoder
from nl2policy.trees import Tree, from_tokens

if TYPE_CHECKING:
    from nl2policy.language.findings import Findings
    from nl2policy.language.translator import TrainedTranslator

MAX_STEPS = 15


Allow = Callable[[tuple[str, ...], Slot], Optional[frozenset[str]]]
"""An extra restriction on decoding: for the tokens so far and the open slot, the tokens that
may go there (None: any the grammar allows). Clarifying answers are one (clarify.py)."""
Hypothesis = tuple[Optional[Tree], dict[int, float], float]
"""A finished hypothesis: its tree (None if no tree fits), each node's probability, its score."""


def tree_probability(node_probs: dict[int, float]) -> float:
    """The decoder's probability of the whole tree (the product over its nodes, under the grammar
    alone, also where `allow` held the search): the confidence of an on-topic translation, before
    the topic check scales it, and what clarify's Bayes' rule weighs each tree by."""
    return math.prod(node_probs.values())


def ranking_score(score: float, nodes: int, length_norm: float) -> float:
    """How the beam ranks a finished tree of `nodes` nodes whose log-probabilities sum to `score`:
    per node (to the power `length_norm`), or the sum itself when `length_norm` is 0."""
    return score / max(1, nodes) ** length_norm if length_norm else score


def beam_search(model: TrainedTranslator, batch: Batch, texts: list[str],
                found: Optional[Sequence[Findings]] = None) -> list[tuple[Tree, dict[int, float]]]:
    """The best tree of each text (see `search`)."""
    return [hyps[0][:2] for hyps in search(model, batch, texts, found)]


def search(model: TrainedTranslator, batch: Batch, texts: list[str], found: Optional[Sequence[Findings]] = None,
           allow: Optional[Sequence[Optional[Allow]]] = None, width: Optional[int] = None) -> list[list[Hypothesis]]:
    """Beam search under the grammar mask over the members' averaged step probabilities
    (`model.beam` hypotheses per description; 1 is greedy). A tree's score is the sum of its
    nodes' log-probabilities, so a subtree the text does not support costs its every node
    (the reported probabilities stay the model's own). With a `findings_cost`, the score also
    adds that many times the log-probability the text's findings (`found`, one per text; read
    here when not given) give the tree's question set, action set and root, paid part by part as
    the tree takes shape, so the beam explores the trees the text was read to describe.

    `allow` (one per text, or None) restricts each text's hypotheses further as they grow, so a
    tree that breaks it is never built, while every node keeps the probability the model gives it
    under the grammar alone (a tree's probability stays comparable with and without `allow`);
    `width` overrides the beam. Returns each text's finished
    hypotheses, best first; where none is left, one (None, {}, -inf)."""
    vocab = get_domain(model.domain).vocab
    names = model.tree_tokens
    index = {t: i for i, t in enumerate(names)}
    findings_cost = model.decoding("findings_cost")
    length_norm = model.decoding("length_norm")
    B, K = len(texts), max(1, width or model.beam or model.cfg.beam)
    if not findings_cost or model.findings is None:
        found = None
    elif found is None:
        found = model.findings.read(texts)
    if found is not None:
        # a tree's findings term, log P(its question set, action set, root), split over the search:
        # a label's log P(present) when a node first uses it, the root's log-probability at the
        # first step, and log P(absent) of every label it never used once it is finished; so the
        # beam compares hypotheses by (nearly) what they will finally be scored by
        present = torch.tensor([[math.log(max(f.asks.get(t, f.takes.get(t, 1.0)), 1e-6)) for t in names] for f in found])
        absent = torch.tensor([[math.log(max(1 - f.asks.get(t, f.takes.get(t, 0.0)), 1e-6)) for t in names] for f in found])
        root_prior = torch.tensor([[math.log(max(f.root.get(t, 0.0), 1e-6)) for t in names] for f in found])
        used = torch.zeros(B * K, len(names), dtype=torch.bool)
        charged = torch.zeros(B * K, dtype=torch.bool)
    state = DecoderState(model, batch, copies=K)
    prefixes: list[list[str]] = [[] for _ in range(B * K)]
    probs: list[dict[int, float]] = [{} for _ in range(B * K)]
    score = torch.full((B, K), -math.inf)
    score[:, 0] = 0.0  # the copies start identical: only the first may expand
    # hypotheses share prefixes and slots: each is read once per search, not walked from the root
    # for every hypothesis at every step
    slot_after: dict[tuple[str, ...], Optional[Slot]] = {}
    allowed: dict[Optional[Slot], torch.Tensor] = {None: torch.arange(len(names)) == 0}  # finished: a placeholder
    restricted: dict[tuple[int, tuple[str, ...]], Optional[torch.Tensor]] = {}
    for step in range(MAX_STEPS):
        slots = []
        for prefix in map(tuple, prefixes):
            if prefix not in slot_after:
                slot_after[prefix] = next_slot(prefix, vocab)
            slots.append(slot_after[prefix])
        if all(s is None for s in slots):
            break
        for s in slots:
            if s not in allowed:
                allowed[s] = torch.zeros(len(names), dtype=torch.bool)
                allowed[s][[index[a] for a in allowed_tokens(s, vocab)]] = True
        grammar = torch.stack([allowed[s] for s in slots])  # a finished hypothesis continues at no cost
        mask = grammar.clone()
        if allow is not None:
            for r, (prefix, s) in enumerate(zip(prefixes, slots)):
                rule = allow[r // K]
                key = (r // K, tuple(prefix))
                if rule is not None and s is not None:
                    if key not in restricted:
                        only = rule(key[1], s)
                        restricted[key] = None if only is None else torch.tensor([t in only for t in names])
                    if restricted[key] is not None:
                        mask[r] = mask[r] & restricted[key]
        parent = torch.tensor([-1 if s is None else s.parent for s in slots])
        branch = torch.tensor([0 if s is None else s.branch for s in slots])
        logits = state.step(parent, branch)  # (members, B*K, tokens)
        # the model's own probabilities under the grammar: `allow` decides which trees are built, not
        # what the model thinks of them. Renormalized over what `allow` leaves, a slot an answer
        # narrows to one token would cost nothing, and the trees that pass through such slots would
        # outrank the ones the model reads in the text (results/clarify/README.md)
        p = torch.softmax(logits.masked_fill(~grammar, -1e9), -1).mean(0)
        done = torch.tensor([s is None for s in slots])
        if found is not None:  # hypotheses that have just finished pay for the labels they never used
            fresh = done & ~charged
            score = score + findings_cost * (absent.repeat_interleave(K, 0) * ~used * fresh[:, None]).sum(-1).view(B, K)
            charged = charged | done
        logp = torch.where(mask, p.clamp(min=1e-12).log(), torch.tensor(-math.inf))
        if found is not None:  # the learned findings, paid as the tree takes shape (findings.py)
            logp = logp + findings_cost * present.repeat_interleave(K, 0) * ~used
            if step == 0:
                logp = logp + findings_cost * root_prior.repeat_interleave(K, 0)
        logp[done] = torch.where(mask[done], 0.0, -math.inf)
        total = (score.view(B * K, 1) + logp).view(B, K * len(names))
        ranked = total
        if length_norm:  # rank by log-probability per node: a finished small tree against a growing larger one
            nodes = torch.tensor([len(q) + (s is not None) for q, s in zip(prefixes, slots)], dtype=torch.float)
            ranked = (total.view(B * K, -1) / nodes.clamp(min=1)[:, None] ** length_norm).view(B, -1)
        flat = ranked.topk(K, -1).indices  # ties keep the lower index: greedy's argmax when K = 1
        best = total.gather(1, flat)
        source = (torch.arange(B)[:, None] * K + flat // len(names)).view(-1)
        choice = (flat % len(names)).view(-1)
        score = best
        prefixes = [list(prefixes[r]) for r in source.tolist()]
        probs = [dict(probs[r]) for r in source.tolist()]
        for r, (src, c) in enumerate(zip(source.tolist(), choice.tolist())):
            if slots[src] is not None:
                prefixes[r].append(names[c])
                probs[r][slots[src].grid] = float(p[src, c])
        state.reorder(source)
        state.push(choice)
        if found is not None:
            used, charged = used[source].clone(), charged[source]
            live = torch.tensor([slots[src] is not None for src in source.tolist()])
            used[torch.arange(B * K)[live], choice[live]] = True
    if found is not None:  # those that finished at the last step
        score = score + findings_cost * (absent.repeat_interleave(K, 0) * ~used * ~charged[:, None]).sum(-1).view(B, K)
    flat = score.view(-1).tolist()
    trees = [from_tokens(p, vocab) if math.isfinite(flat[r]) and p and next_slot(p, vocab) is None else None
             for r, p in enumerate(prefixes)]
    rank = [ranking_score(f, len(p), length_norm) for f, p in zip(flat, prefixes)]
    out = []
    for b in range(B):  # beams stay sorted, but finished ones may have been overtaken
        rows = sorted((r for r in range(b * K, b * K + K) if trees[r] is not None), key=lambda r: -rank[r])
        out.append([(trees[r], probs[r], flat[r]) for r in rows] or [(None, {}, -math.inf)])
    return out


class DecoderState:
    """Every member's running decoder over a batch of hypotheses: the state after each step
    (a node's children are fed its state), the tokens chosen, the last attention context.

    Kept as tensors with a step axis, so the beam search reorders hypotheses with one index per
    tensor. The shipped network runs all members at once (StackedEncoder, StackedDecoder); the
    lab's baselines (or any, with `stack_members` off), member by member: same arithmetic."""

    def __init__(self, model: TrainedTranslator, batch: Batch, copies: int = 1) -> None:
        """`copies` hypotheses per description (rows b*copies ... b*copies+copies-1): each
        description is encoded once, then its memory repeated."""
        self.nets = model.nets[:model.ensemble] if model.ensemble else model.nets
        stack = model.stack_members and all(net.stackable for net in self.nets)
        memories = StackedEncoder(self.nets).encode(batch) if stack else [net.encode(batch) for net in self.nets]
        self.memories = [{k: v.repeat_interleave(copies, 0) for k, v in m.items()} for m in memories]
        h0 = torch.stack([m["h0"] for m in self.memories])  # (E, B, h)
        E, B, h = h0.shape
        self.states = h0.new_zeros(E, B, MAX_STEPS + 1, h)
        self.states[:, :, 0] = h0
        self.tokens = torch.full((B, MAX_STEPS + 1), self.nets[0].start_id, dtype=torch.long)
        self.ctx = h0.new_zeros(E, B, self.nets[0].out.in_features - h)
        self.t = 0
        self.stacked = None
        if stack:
            self.stacked = StackedDecoder(self.nets)
            self.words = torch.stack([m["words"] for m in self.memories])

    def step(self, parent: torch.Tensor, branch: torch.Tensor) -> torch.Tensor:
        """Every member's logits (E, B, V) for the next slot, whose parent is at token position
        `parent` (-1: the root, fed the start state)."""
        rows, src = torch.arange(len(parent)), parent + 1
        h_prev, prev_tok = self.states[:, :, self.t], self.tokens[:, self.t]
        h_parent, parent_tok = self.states[:, rows, src], self.tokens[rows, src]
        if self.stacked is not None:
            h, ctx, logits = self.stacked.step(self.words, self.memories[0]["mask"], h_prev, self.ctx, prev_tok,
                                               h_parent, parent_tok, branch)
        else:
            out = [net.step(m, h_prev[e], self.ctx[e], prev_tok, h_parent[e], parent_tok, branch)
                   for e, (net, m) in enumerate(zip(self.nets, self.memories))]
            h, ctx, logits = (torch.stack(x) for x in zip(*out))
        self.states[:, :, self.t + 1] = h
        self.ctx = ctx
        return logits

    def reorder(self, source: torch.Tensor) -> None:
        """Hypothesis i continues hypothesis source[i] (of the same description)."""
        self.states, self.tokens, self.ctx = self.states[:, source], self.tokens[source], self.ctx[:, source]

    def push(self, chosen: torch.Tensor) -> None:
        self.t += 1
        self.tokens[:, self.t] = chosen


def preorder_slots(tree: Tree, slot: int = 0) -> list[int]:
    """Grid slots of a tree's nodes in pre-order."""
    if not hasattr(tree, "question"):
        return [slot]
    return [slot] + preorder_slots(tree.yes, 2 * slot + 1) + preorder_slots(tree.no, 2 * slot + 2)
