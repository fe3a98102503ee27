"""A differentiable decision tree (DDT) of any shape, evaluated for a whole batch at once.

Node n answers ``yes`` softly: ``s_n(x) = sigmoid(gamma * (w_n . x - c_n))``. A leaf's path
probability is the product, over the nodes on its path, of ``s_n`` (yes side) or
``1 - s_n`` (no side); the action distribution is the path-weighted mixture of the leaves'
softmax distributions. The shape lives in two fixed 0/1 matrices, ``yes_path`` and
``no_path`` (leaves x nodes): entry [l, n] is 1 when leaf l lies on node n's yes (no) side.
Log path probabilities are then two matrix products of log-sigmoids, so the forward pass has
no Python loop over nodes and works in log space (no underflow, exact gradients).

``gamma`` is a frozen buffer, not a parameter: it sets how sharp a node is, and keeping it
fixed keeps each node a readable threshold test, so that discretizing the trained DDT back to
a tree (``convert.ddt_to_tree``) changes the policy little. ``w`` and ``c`` still learn.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn
import torch.nn.functional as F


@dataclass(frozen=True)
class Shape:
    """A tree shape: ``yes_child[n]`` / ``no_child[n]`` is ``("node", i)`` or ``("leaf", j)``."""

    yes_child: tuple[tuple[str, int], ...]
    no_child: tuple[tuple[str, int], ...]
    leaves: int

    @property
    def nodes(self) -> int:
        return len(self.yes_child)

    def path_matrices(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(yes_path, no_path), each (leaves, nodes), by walking down from node 0."""
        yes = torch.zeros(self.leaves, self.nodes)
        no = torch.zeros(self.leaves, self.nodes)
        if self.nodes == 0:
            return yes, no
        stack: list[tuple[tuple[str, int], list[tuple[int, bool]]]] = [(("node", 0), [])]
        while stack:
            (kind, index), path = stack.pop()
            if kind == "leaf":
                for n, went_yes in path:
                    (yes if went_yes else no)[index, n] = 1.0
                continue
            stack.append((self.yes_child[index], path + [(index, True)]))
            stack.append((self.no_child[index], path + [(index, False)]))
        return yes, no


def complete_shape(depth: int) -> Shape:
    """A complete binary tree with ``depth`` node levels (2**depth leaves), nodes and leaves
    numbered breadth-first (the grid's order)."""
    nodes, leaves = 2**depth - 1, 2**depth

    def child(slot: int) -> tuple[str, int]:
        return ("node", slot) if slot < nodes else ("leaf", slot - nodes)

    return Shape(tuple(child(2 * n + 1) for n in range(nodes)), tuple(child(2 * n + 2) for n in range(nodes)), leaves)


class DDT(nn.Module):
    """Soft decision tree over ``features`` inputs with ``actions`` outputs.

    ``forward(x)`` returns the log of the mixture's action probabilities, shape (batch, actions):
    valid logits for a categorical distribution.
    """

    def __init__(self, shape: Shape, features: int, actions: int, gamma: float) -> None:
        super().__init__()
        self.shape = shape
        yes_path, no_path = shape.path_matrices()
        self.register_buffer("yes_path", yes_path)
        self.register_buffer("no_path", no_path)
        self.register_buffer("gamma", torch.tensor(float(gamma)))
        self.weights = nn.Parameter(torch.zeros(shape.nodes, features))
        self.comparators = nn.Parameter(torch.zeros(shape.nodes))
        self.leaf_logits = nn.Parameter(torch.zeros(shape.leaves, actions))
        # Leaf softmax temperature, set during training by optimize.Anneal from 1 down to
        # `anneal_to` (1: no annealing), so the soft policy PPO trains ends near the tree read
        # from it. Not saved: the schedule sets it again from the step count.
        self.register_buffer("leaf_temperature", torch.tensor(1.0), persistent=False)
        self.anneal_to, self.anneal_from = 1.0, 0.0  # the line starts `anneal_from` of the way in
        # The same for the nodes: a multiple of gamma, from 1 up to `sharpen_to` on a line that
        # starts `sharpen_from` of the way into the run, so that the soft policy's paths end
        # near the crisp tree's too while PPO could still move its questions earlier on.
        self.register_buffer("node_sharpness", torch.tensor(1.0), persistent=False)
        self.sharpen_to, self.sharpen_from = 1.0, 0.0

    def __setstate__(self, state: dict) -> None:
        # A DDT pickled before the annealing buffers existed (a checkpoint's policy_kwargs) loads
        # with them at their neutral values, so old runs resume instead of failing.
        super().__setstate__(state)
        for name in ("leaf_temperature", "node_sharpness"):
            if name not in self._buffers:
                self.register_buffer(name, torch.tensor(1.0), persistent=False)
        for name, value in (("anneal_to", 1.0), ("anneal_from", 0.0), ("sharpen_to", 1.0), ("sharpen_from", 0.0)):
            if not hasattr(self, name):
                setattr(self, name, value)

    def node_logits(self, x: torch.Tensor) -> torch.Tensor:
        """gamma * (w_n . x - c_n) for every node, shape (batch, nodes), times the annealing's
        node sharpness (1 outside training with ``node_sharpness_end``)."""
        return self.gamma * self.node_sharpness * (x @ self.weights.T - self.comparators)

    def log_path_probs(self, x: torch.Tensor) -> torch.Tensor:
        """log P(reach leaf l | x), shape (batch, leaves)."""
        z = self.node_logits(x)
        return F.logsigmoid(z) @ self.yes_path.T + F.logsigmoid(-z) @ self.no_path.T

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # log sum_l P(l|x) softmax(leaf_l): shift by the most likely leaf's log path
        # probability, mix in probability space with one matmul (2x faster than a logsumexp
        # over a (batch, leaves, actions) tensor), shift back. The floor only bites for an
        # action every leaf gives < 1e-30, and keeps its log finite for SB3's entropy.
        log_path = self.log_path_probs(x)
        top = log_path.max(dim=1, keepdim=True).values
        mixture = torch.exp(log_path - top) @ torch.softmax(self.leaf_logits / self.leaf_temperature, dim=-1)
        return torch.log(mixture.clamp_min(1e-30)) + top

    @torch.no_grad()
    def greedy(self, x: torch.Tensor) -> torch.Tensor:
        """The most probable action under the mixture, shape (batch,)."""
        return self.forward(x).argmax(dim=-1)


def random_ddt(features: int, actions: int, gamma: float, depth: int = 3, seed: int = 0) -> DDT:
    """The paper's random-DDT baseline: a complete tree (8 leaves at depth 3) with random
    tests. Each node gets unit-norm random weights and a comparator that puts its threshold
    inside the [0, 1] feature box (so every node actually splits the data); leaves start
    near uniform."""
    gen = torch.Generator().manual_seed(seed)
    ddt = DDT(complete_shape(depth), features, actions, gamma)
    with torch.no_grad():
        w = torch.randn(ddt.shape.nodes, features, generator=gen)
        ddt.weights.copy_(w / w.norm(dim=1, keepdim=True))
        centre = torch.rand(ddt.shape.nodes, features, generator=gen)
        ddt.comparators.copy_((ddt.weights * centre).sum(dim=1))
        ddt.leaf_logits.copy_(0.01 * torch.randn(ddt.shape.leaves, actions, generator=gen))
    return ddt
