"""DDT forward+backward throughput at batch 4096: the matrix form (nl2policy.policy.ddt)
against a straightforward implementation that loops over leaves and the nodes on each path.

Run: .venv/bin/python benchmarks/ddt_throughput.py   (one thread, side by side, prints the ratio)
"""

from __future__ import annotations

import time

import torch

from nl2policy.policy.ddt import DDT, random_ddt

BATCH, REPEATS = 4096, 50


def loop_log_probs(ddt: DDT, x: torch.Tensor) -> torch.Tensor:
    """Per-node loop: for each leaf, multiply the sigmoids of the nodes on its path."""
    leaf_probs = torch.softmax(ddt.leaf_logits, -1)
    mixture = torch.zeros(x.shape[0], ddt.leaf_logits.shape[1])
    for leaf in range(ddt.shape.leaves):
        p = torch.ones(x.shape[0])
        for n in range(ddt.shape.nodes):
            if ddt.yes_path[leaf, n] or ddt.no_path[leaf, n]:
                s = torch.sigmoid(ddt.gamma * (x @ ddt.weights[n] - ddt.comparators[n]))
                p = p * (s if ddt.yes_path[leaf, n] else 1 - s)
        mixture = mixture + p[:, None] * leaf_probs[leaf]
    return mixture.log()


def time_it(fn, ddt: DDT, x: torch.Tensor) -> float:
    """Seconds per forward+backward (mean of REPEATS after one warm-up)."""
    for step in range(REPEATS + 1):
        if step == 1:
            start = time.perf_counter()
        ddt.zero_grad()
        fn(x)[:, 0].sum().backward()
    return (time.perf_counter() - start) / REPEATS


def main() -> None:
    torch.set_num_threads(1)
    ddt = random_ddt(features=6, actions=5, gamma=10.0, depth=3, seed=0)
    x = torch.rand(BATCH, 6)
    assert torch.allclose(ddt(x), loop_log_probs(ddt, x), atol=1e-4)
    matrix = time_it(ddt, ddt, x)
    loop = time_it(lambda v: loop_log_probs(ddt, v), ddt, x)
    print(f"DDT 7 nodes / 8 leaves, batch {BATCH}, forward+backward, 1 thread, mean of {REPEATS}")
    print(f"  matrix form : {matrix * 1e3:8.3f} ms  ({BATCH / matrix:12,.0f} states/s)")
    print(f"  per-node loop: {loop * 1e3:8.3f} ms  ({BATCH / loop:12,.0f} states/s)")
    print(f"  speed-up (loop / matrix): {loop / matrix:.2f}x")


if __name__ == "__main__":
    main()
