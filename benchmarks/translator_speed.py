"""How long the default translator takes to train for one domain (budget: 5 minutes) and to
translate one description (budget: 20 ms), on this machine.

Trains into a temporary NL2POLICY_HOME so a user's saved model is not touched.
Run: .venv/bin/python benchmarks/translator_speed.py [--domain taxi] [--threads 2] [--latency-threads 1] [--out FILE]
Training uses both cores by default (it is a batch job that has the machine); translation one
torch thread (a server answers each request on one thread, and for one short text a second
thread mostly adds synchronisation). The load average (printed) says how busy the machine was.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", default="taxi")
    parser.add_argument("--threads", type=int, default=2, help="torch threads while training")
    parser.add_argument("--latency-threads", type=int, default=1, help="torch threads while translating")
    parser.add_argument("--out", default=None, help="Also write the report to this file")
    parser.add_argument("--model", default=None)
    args = parser.parse_args()
    os.environ["NL2POLICY_HOME"] = tempfile.mkdtemp(prefix="nl2policy-bench-")
    import torch

    torch.set_num_threads(args.threads)
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.models.config import DEFAULT_MODEL
    from nl2policy.language.translate import get_model, train_default, translate

    name = args.model or DEFAULT_MODEL
    load_start = os.getloadavg()[0]
    start = time.perf_counter()
    train_default(args.domain, name)
    train_s = time.perf_counter() - start
    torch.set_num_threads(args.latency_threads)
    get_model(args.domain, name)
    specs = load_corpus(args.domain)
    translate(args.domain, "warm-up: " + specs[0].description, name)  # loads MiniLM; not a measured text
    latencies, words, features = [], [], []
    translator = get_model(args.domain, name).translator
    for spec in specs:
        t0 = time.perf_counter()
        translate(args.domain, spec.description, name)
        latencies.append(1000 * (time.perf_counter() - t0))
        words.append(len(spec.description.split()))
        translator.cache.store.clear()
        t0 = time.perf_counter()
        translator.encode(spec.description)  # the MiniLM features alone, for the split below
        features.append(1000 * (time.perf_counter() - t0))
    latencies.sort()
    # side by side (MiniLM cached, rounds interleaved): the ensemble's decoder as one stacked batch
    # vs member by member, and the config's beam vs greedy decoding
    variants = {"stacked": (True, None), "member by member": (False, None), "stacked, greedy": (True, 1)}
    network_ms: dict[str, list[float]] = {v: [] for v in variants}
    for spec in specs:
        translator.encode(spec.description)  # MiniLM features cached for every timing
    for i, spec in enumerate(specs):
        order = list(variants)[i % len(variants):] + list(variants)[:i % len(variants)]
        for variant in order:
            translator.stack_members, translator.beam = variants[variant]
            t0 = time.perf_counter()
            translator.predict([spec.description])
            network_ms[variant].append(1000 * (time.perf_counter() - t0))
    translator.stack_members, translator.beam = True, None
    net = {v: statistics.median(ms) for v, ms in network_ms.items()}
    median = statistics.median(latencies)
    p90 = latencies[int(0.9 * len(latencies))]
    lines = [f"command: .venv/bin/python benchmarks/translator_speed.py --domain {args.domain} --threads {args.threads} "
             f"--latency-threads {args.latency_threads}",
             f"model {name}, domain {args.domain}, {args.threads} torch threads training, {args.latency_threads} translating, "
             f"{os.cpu_count()} cores, "
             f"load average (1 min) at start {load_start:.1f}, at end {os.getloadavg()[0]:.1f}",
             f"training time: {train_s:.1f} s (budget 300 s) -> {'OK' if train_s < 300 else 'OVER'}",
             f"translation latency over {len(specs)} corpus descriptions (mean {statistics.mean(words):.0f} words), "
             f"model loaded, each text new to the MiniLM cache: median {median:.1f} ms, p90 {p90:.1f} ms, "
             f"max {latencies[-1]:.1f} ms (budget 20 ms) -> {'OK' if median < 20 else 'OVER'}",
             f"of which MiniLM features (tokenize, run, align to words): median {statistics.median(features):.1f} ms",
             f"network part ({len(translator.nets)} members, beam {translator.cfg.beam}, MiniLM cached), rounds "
             f"interleaved: stacked decoder median {net['stacked']:.2f} ms vs member by member "
             f"{net['member by member']:.2f} ms -> {net['member by member'] / net['stacked']:.2f}x; "
             f"greedy (stacked) {net['stacked, greedy']:.2f} ms: the beam costs {net['stacked'] / net['stacked, greedy']:.2f}x"]
    print("\n".join(lines))
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
