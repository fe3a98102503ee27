"""What MiniLM costs per description, the part of a translation no decoder change can remove:
float32 against the int8 model that training and translation use, with all six transformer
layers (the default's) and with three, on one and on two torch threads, and the int8 six-layer
model as translation runs it, traced with TorchScript (pretrained._forward), beside it eager.

Run: .venv/bin/python benchmarks/minilm_speed.py [--texts 100] [--out FILE]
The corpus's first descriptions of both domains (word pieces as the translator reads them, one
256-piece window), every variant timed on every text in interleaved rounds so that a change in
the machine's load falls on all of them alike; medians, and ratios against the default
(int8, six layers, one thread, eager).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the lab (experiments/) beside benchmarks/


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--texts", type=int, default=100, help="descriptions per domain")
    parser.add_argument("--out", default=None, help="Also write the report to this file")
    args = parser.parse_args()
    from nl2policy.language.corpus import load_corpus
    from experiments.translation.evaluate import machine
    from nl2policy.language.models.pretrained import MAX_PIECES, _forward, _HiddenStates, _load

    tokenizer = _load(6, True)[0]
    texts = [s.description for d in ("taxi", "highway") for s in load_corpus(d)[:args.texts]]
    ids = [torch.tensor([tokenizer(t)["input_ids"][:MAX_PIECES]]) for t in texts]
    # (layers, int8, threads, traced) -> ids -> every layer's states
    variants = {(layers, int8, threads, False): _HiddenStates(_load(layers, int8)[1]).eval()
                for layers in (6, 3) for int8 in (True, False) for threads in (1, 2)}
    variants.update({(6, True, threads, True): _forward(6) for threads in (1, 2)})
    times: dict[tuple, list[float]] = {v: [] for v in variants}
    with torch.inference_mode():
        for v, model in variants.items():  # warm-up
            torch.set_num_threads(v[2])
            model(ids[0])
        order = list(variants)
        for i, x in enumerate(ids):
            for v in order[i % len(order):] + order[:i % len(order)]:
                torch.set_num_threads(v[2])
                t0 = time.perf_counter()
                variants[v](x)
                times[v].append(1000 * (time.perf_counter() - t0))
    med = {v: statistics.median(ts) for v, ts in times.items()}
    base = med[(6, True, 1, False)]
    lines = ["command: .venv/bin/python benchmarks/minilm_speed.py" + (f" --texts {args.texts}" if args.texts != 100 else ""),
             f"{len(texts)} descriptions (median {statistics.median(x.shape[1] for x in ids):.0f} word pieces), "
             f"{os.cpu_count()} cores ({machine()}), load average (1 min) {os.getloadavg()[0]:.1f}",
             "MiniLM forward per description, median ms (x: time against int8, 6 layers, 1 thread, eager):"]
    for (layers, int8, threads, traced), ms in med.items():
        lines.append(f"  {'int8' if int8 else 'float32'}, {layers} layers, {threads} thread{'s' if threads > 1 else ''}"
                     f"{', traced (as translation runs it)' if traced else ''}: {ms:.1f} ms ({ms / base:.2f}x)")
    print("\n".join(lines))
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
