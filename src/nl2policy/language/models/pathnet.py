"""The path-conditioned node classifier: the default translator's decoder.

Why: a node's label (a question or an action) depends only on the description and on the
(question, answer) literals from the root to that node ("if it has a passenger and traffic
is heavy, ..."). So instead of a sequential decoder whose state must carry the whole prefix,
each node is classified independently from the description's word states and a vector of
its path: the sum of one embedding per literal on the path, one for the parent literal and
one for the depth. Two hops of attention over the words read the part of the text about that
path. Training sees every node of every tree (7-15 examples per description, not one long
sequence), which matters with only 160 descriptions per fold.

Decoding runs from the root: questions already on the path, and every question at depth 3,
are masked; when a node's yes and no subtrees come out identical it is replaced by that
subtree (an equivalent, valid tree).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn

from nl2policy.trees import MAX_DEPTH, Leaf, Node, Tree


@dataclass
class PathBatch:
    """K tree nodes to classify: which description each belongs to (`doc`, into the encoded
    batch), its path literals (K, MAX_DEPTH) padded with `pad`, its parent literal and depth,
    and the labels the grammar allows there (K, V)."""

    doc: torch.Tensor
    literals: torch.Tensor
    parent: torch.Tensor
    depth: torch.Tensor
    allowed: torch.Tensor


class PathDecoder(nn.Module):
    def __init__(self, n_questions: int, n_labels: int, mem: int, hidden: int, dropout: float) -> None:
        super().__init__()
        self.n_questions = n_questions
        self.pad = 2 * n_questions  # literal id 2q + answer (1 yes, 0 no); pad = none
        self.literal = nn.Embedding(2 * n_questions + 1, mem, padding_idx=self.pad)
        self.parent = nn.Embedding(2 * n_questions + 1, mem)
        self.depth = nn.Embedding(MAX_DEPTH + 1, mem)
        self.query1 = nn.Linear(mem, mem)
        self.query2 = nn.Linear(2 * mem, mem)
        self.head = nn.Sequential(nn.Linear(3 * mem, hidden), nn.Tanh(), nn.Dropout(dropout), nn.Linear(hidden, n_labels))

    def forward(self, words: torch.Tensor, mask: torch.Tensor, nodes: PathBatch) -> torch.Tensor:
        """Logits (K, V), with labels the grammar forbids at -1e9."""
        path = self.literal(nodes.literals).sum(1) + self.parent(nodes.parent) + self.depth(nodes.depth)
        U, M = words[nodes.doc], mask[nodes.doc]
        att1 = torch.softmax(torch.einsum("knd,kd->kn", U, self.query1(path)).masked_fill(~M, -1e9), -1)
        ctx1 = torch.einsum("kn,knd->kd", att1, U)
        att2 = torch.softmax(torch.einsum("knd,kd->kn", U, self.query2(torch.cat([path, ctx1], -1))).masked_fill(~M, -1e9), -1)
        ctx2 = torch.einsum("kn,knd->kd", att2, U)
        return self.head(torch.cat([path, ctx1, ctx2], -1)).masked_fill(~nodes.allowed, -1e9)

    def node_batch(self, doc: list[int], paths: list[tuple[tuple[int, int], ...]], n_labels: int) -> PathBatch:
        """Tensors for nodes given as (doc index, path of (question index, answer 0/1))."""
        K = len(paths)
        literals = torch.full((K, MAX_DEPTH), self.pad, dtype=torch.long)
        parent = torch.full((K,), self.pad, dtype=torch.long)
        depth = torch.zeros(K, dtype=torch.long)
        allowed = torch.ones(K, n_labels, dtype=torch.bool)
        for k, path in enumerate(paths):
            for j, (q, a) in enumerate(path):
                literals[k, j] = 2 * q + a
                allowed[k, q] = False
            if path:
                parent[k] = 2 * path[-1][0] + path[-1][1]
            depth[k] = len(path)
            if len(path) >= MAX_DEPTH:
                allowed[k, : self.n_questions] = False
        return PathBatch(torch.tensor(doc, dtype=torch.long), literals, parent, depth, allowed)


def tree_nodes(tree: Tree, labels: list[str], questions: list[str], path: tuple = ()) -> list[tuple[tuple, int]]:
    """(path, label index) for every node of a gold tree: the training examples."""
    if isinstance(tree, Leaf):
        return [(path, labels.index(tree.action))]
    q = questions.index(tree.question)
    return ([(path, labels.index(tree.question))] + tree_nodes(tree.yes, labels, questions, path + ((q, 1),))
            + tree_nodes(tree.no, labels, questions, path + ((q, 0),)))


def decode_paths(decoder: PathDecoder, words: torch.Tensor, mask: torch.Tensor, labels: list[str],
                 n_questions: int, logits_fn=None) -> list[tuple[Tree, list[float]]]:
    """Greedy top-down decoding of every description in the batch, one tree level at a time.
    Returns (tree, probabilities of its nodes in pre-order). `logits_fn(nodes)` (optional)
    replaces the decoder's logits, e.g. by an ensemble's averaged log-probabilities."""
    B = words.shape[0]
    chosen: dict[tuple[int, tuple], tuple[int, float]] = {}
    frontier = [(b, ()) for b in range(B)]
    while frontier:
        nodes = decoder.node_batch([b for b, _ in frontier], [p for _, p in frontier], len(labels))
        logp = logits_fn(nodes) if logits_fn else torch.log_softmax(decoder(words, mask, nodes), -1)
        best = logp.argmax(-1)
        nxt = []
        for k, (b, path) in enumerate(frontier):
            lab = int(best[k])
            chosen[(b, path)] = (lab, float(logp[k, lab].exp()))
            if lab < n_questions:
                nxt += [(b, path + ((lab, 1),)), (b, path + ((lab, 0),))]
        frontier = nxt

    def build(b: int, path: tuple) -> tuple[Tree, list[float]]:
        lab, prob = chosen[(b, path)]
        if lab >= n_questions:
            return Leaf(labels[lab]), [prob]
        yes, yes_p = build(b, path + ((lab, 1),))
        no, no_p = build(b, path + ((lab, 0),))
        if yes == no:  # the question changes nothing: keep the (equivalent) subtree
            return yes, yes_p
        return Node(labels[lab], yes, no), [prob] + yes_p + no_p

    return [build(b, ()) for b in range(B)]
