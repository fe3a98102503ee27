"""How long a warm translation takes when the translator asks (budget: a median under 1.5 s),
beside a plain translation of the same texts in the same rounds.

For each description (round 2 of the corpus, the writers who described sampled trees), one
round times: the first translation (with the question it asks, if any), then the translation
with one answer and with two (answered with the first choice that differs from the tree's
action there, so the tree must change). A call with answers replays the questions asked before
them to check that each answer is to the question asked, so it pays for every earlier step too.

Run: .venv/bin/python benchmarks/clarify_speed.py [--domain taxi] [--n 40] [--out FILE]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", default="taxi")
    parser.add_argument("--n", type=int, default=40, help="descriptions")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)  # a server answers each request on one thread
    from nl2policy.language.corpus import load_corpus
    from nl2policy.language.translate import get_model, translate

    get_model(args.domain)
    texts = [s.description for s in load_corpus(args.domain, rounds=(2,))[: args.n]]
    translate(args.domain, texts[0])  # warm: model loaded, first-call costs paid
    times: dict[str, list[float]] = {"plain (no questions)": [], "with its question": [], "1 answer": [], "2 answers": []}
    asked = 0
    for i, text in enumerate(texts):
        # the first call of a text also computes its MiniLM features: the two first calls take turns
        for key in (("plain (no questions)", "with its question") if i % 2 else ("with its question", "plain (no questions)")):
            start = time.perf_counter()
            out = translate(args.domain, text, max_questions=0 if key.startswith("plain") else 3)
            times[key].append(time.perf_counter() - start)
            if key == "with its question":
                result = out
        answers = []
        for key in ("1 answer", "2 answers"):
            if not result.questions:
                break
            q = result.questions[0]
            do = next(a for a, _ in q.choices if a != result.tree.act(dict(q.situation)))
            answers.append({"situation": dict(q.situation), "do": do})
            start = time.perf_counter()
            result = translate(args.domain, text, answers=answers)
            times[key].append(time.perf_counter() - start)
            asked += 1
    command = "command: .venv/bin/python benchmarks/clarify_speed.py " + " ".join(sys.argv[1:])
    lines = [command, f"clarify speed, {args.domain}, model {get_model(args.domain).translator.name}: {len(texts)} round-2 "
             "descriptions, warm, one torch thread, "
             f"load average {os.getloadavg()[0]:.2f}", f"questions answered: {asked}",
             "| call | n | median (ms) | 90th percentile (ms) | median / plain |", "|---|---:|---:|---:|---:|"]
    plain = statistics.median(times["plain (no questions)"])
    for key, xs in times.items():
        if xs:
            xs = sorted(xs)
            lines.append(f"| {key} | {len(xs)} | {1000 * statistics.median(xs):.1f} | {1000 * xs[math.ceil(0.9 * len(xs)) - 1]:.1f} | "
                         f"{statistics.median(xs) / plain:.2f} |")
    slowest = max(statistics.median(xs) for key, xs in times.items() if xs and not key.startswith("plain"))
    lines.append(f"budget: a warm translation with questions, median under 1,500 ms: the slowest call's median is "
                 f"{1000 * slowest:.1f} ms -> {'OK' if slowest < 1.5 else 'OVER'}")
    report = "\n".join(lines)
    print(report)
    if args.out:
        args.out.write_text(report + "\n")


if __name__ == "__main__":
    main()
