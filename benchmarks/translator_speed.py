"""How long the default translator takes to train for one domain (budget: 60 minutes) and to
translate one description warm (budget: a median under 1 s), on this machine.

Trains into a temporary NL2POLICY_HOME so a user's saved model is not touched.
Run: .venv/bin/python benchmarks/translator_speed.py [--domain taxi] [--threads 2] [--latency-threads N] [--out FILE]
     [--latency-only] (no training: the shipped model's latency)
     [--save-to src/nl2policy/domains/taxi] (keep the trained model there: training the shipped
     file and timing it are one run)
Training uses both cores (it is a batch job that has the machine): as the product trains, the
ensemble's members in one process per core (one torch thread each), and, side by side, the
members one after the other in one process with `--threads` torch threads (`--no-compare`
skips that second run). Translation uses one torch thread by default (a server answers each
request on one thread); beside it, in the same rounds, the same texts at torch's default of a
thread per core, as the command line's `translate` runs. Each timing starts with the text new to
the MiniLM cache (the networks and the learned findings read the same features). The load average (printed)
says how busy the machine was.
"""

from __future__ import annotations

import argparse
import atexit
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the lab (experiments/) beside benchmarks/


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", default="taxi")
    parser.add_argument("--threads", type=int, default=2, help="torch threads while training")
    parser.add_argument("--latency-threads", type=int, default=1,
                        help="torch threads while translating (default: 1, as a server's request)")
    parser.add_argument("--out", default=None, help="Also write the report to this file")
    parser.add_argument("--model", default=None)
    parser.add_argument("--no-compare", action="store_true", help="Skip training the members one by one for comparison")
    parser.add_argument("--save-to", type=Path, default=None,
                        help="Save the trained model into this folder (a domain's folder: as its shipped translator)")
    parser.add_argument("--latency-only", action="store_true",
                        help="Skip training: time translation with the shipped model (e.g. at another --latency-threads)")
    args = parser.parse_args()
    scratch = tempfile.mkdtemp(prefix="nl2policy-bench-")  # both trainings' files; removed at exit
    atexit.register(shutil.rmtree, scratch, ignore_errors=True)
    os.environ["NL2POLICY_HOME"] = os.path.join(scratch, "home")
    import torch

    default_threads = torch.get_num_threads()
    torch.set_num_threads(args.threads)
    from nl2policy.language.corpus import load_corpus
    from experiments.translation.evaluate import machine
    from nl2policy.language.dataset import training_pairs
    from nl2policy.language.members import default_workers
    from nl2policy.language.models.pretrained import encode_tokens
    from nl2policy.language.text import split_sentences
    from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
    from nl2policy.language.shipping import train_default
    from nl2policy.language.translate import get_model, shipped_path, translate

    name = args.model or DEFAULT_MODEL
    # one-time loads (WordNet, phrase tables, MiniLM weights, the optimizer's lazy imports)
    # before either timed run, so the first does not pay them for the second
    cfg, specs = MODELS[name], load_corpus(args.domain)
    torch.optim.Adam([torch.zeros(1, requires_grad=True)])
    training_pairs(args.domain, specs[:5], range(5), cfg, 0)
    if cfg.minilm:
        text = specs[0].description
        encode_tokens(text, [t for s in split_sentences(text) for t in s], cfg.minilm_layers)
    load_start = os.getloadavg()[0]
    workers = default_workers(cfg)
    train_s = one_by_one_s = None
    if not args.latency_only:
        start = time.perf_counter()
        # members side by side, one process per core
        trained = train_default(args.domain, name, out=args.save_to)
        train_s = time.perf_counter() - start
        shipped = shipped_path(args.domain, name)
        same_as_shipped = "no shipped file"
        if trained.resolve() == shipped.resolve():
            same_as_shipped = "this run trained it (--save-to)"
        elif shipped.is_file():  # the shipped file was trained one member at a time, one thread
            a, b = (torch.load(p, weights_only=False)["nets"] for p in (trained, shipped))
            same_as_shipped = "yes" if all(torch.equal(x[k], y[k]) for x, y in zip(a, b, strict=True) for k in x) else "NO"
        if not args.no_compare:
            start = time.perf_counter()
            train_default(args.domain, name, out=Path(scratch) / "one-by-one", workers=1)
            one_by_one_s = time.perf_counter() - start
    latency_threads = args.latency_threads
    torch.set_num_threads(latency_threads)
    get_model(args.domain, name)
    translate(args.domain, "warm-up: " + specs[0].description, name)  # loads MiniLM; not a measured text
    translator = get_model(args.domain, name).translator
    # each text is new to the MiniLM cache each time it is timed, so each timing pays what a new request pays

    def forget() -> None:
        translator.cache.store.clear()

    settings = {"asked": latency_threads, "torch default": default_threads}
    latency: dict[str, list[float]] = {k: [] for k in settings}
    words, features = [], []
    for i, spec in enumerate(specs):  # the two settings in alternating order, text by text
        for setting in (list(settings) if i % 2 == 0 else list(settings)[::-1]):
            torch.set_num_threads(settings[setting])
            forget()
            t0 = time.perf_counter()
            translate(args.domain, spec.description, name)
            latency[setting].append(1000 * (time.perf_counter() - t0))
        torch.set_num_threads(latency_threads)
        words.append(len(spec.description.split()))
        forget()
        t0 = time.perf_counter()
        translator.encode(spec.description)  # the MiniLM features alone, for the split below
        features.append(1000 * (time.perf_counter() - t0))
    latencies = sorted(latency["asked"])
    # side by side (MiniLM cached, rounds interleaved): the ensemble's encoders and decoders as one
    # stacked batch vs member by member, the config's beam vs greedy decoding, and with vs without each of the
    # learned findings (the translator's overrides of its config; None: the config's own)
    variants = {"stacked": {}, "member by member": {"stack_members": False}, "stacked, greedy": {"beam": 1}}
    if translator.cfg.findings_cost:  # the findings weigh the beam (v3); v7's give the warnings alone
        variants["stacked, no findings"] = {"findings_cost": 0.0}
    defaults = {"stack_members": True, "beam": None, "findings_cost": None}
    network_ms: dict[str, list[float]] = {v: [] for v in variants}
    for spec in specs:
        translator.encode(spec.description)  # MiniLM features cached for every timing
    for i, spec in enumerate(specs):
        order = list(variants)[i % len(variants):] + list(variants)[:i % len(variants)]
        for variant in order:
            for attr, value in {**defaults, **variants[variant]}.items():
                setattr(translator, attr, value)
            t0 = time.perf_counter()
            translator.predict([spec.description])
            network_ms[variant].append(1000 * (time.perf_counter() - t0))
    for attr, value in defaults.items():
        setattr(translator, attr, value)
    net = {v: statistics.median(ms) for v, ms in network_ms.items()}
    median = statistics.median(latencies)
    p90 = latencies[int(0.9 * len(latencies))]
    lines = [f"command: .venv/bin/python benchmarks/translator_speed.py --domain {args.domain} --threads {args.threads}"
             + f" --latency-threads {args.latency_threads}"
             + (f" --model {args.model}" if args.model else "")
             + (" --no-compare" if args.no_compare else "") + (" --latency-only" if args.latency_only else "")
             + (f" --save-to {args.save_to}" if args.save_to else ""),
             f"model {name}, domain {args.domain}, {args.threads} torch threads training, {latency_threads} translating "
             f"(torch's default here: {default_threads}), "
             f"{os.cpu_count()} cores ({machine()}), "
             f"load average (1 min) at start {load_start:.1f}, at end {os.getloadavg()[0]:.1f}",
             ("training time: not measured (--latency-only: the shipped model translates)" if train_s is None else
              f"training time: {train_s:.1f} s (budget 3600 s) -> {'OK' if train_s < 3600 else 'OVER'}; "
              f"{workers} worker processes of 1 torch thread (weights bit-identical to the shipped model's: {same_as_shipped})"
              + ("" if one_by_one_s is None else f"; members one by one in one process, {args.threads} torch threads: "
                 f"{one_by_one_s:.1f} s -> workers {one_by_one_s / train_s:.2f}x faster")),
             f"translation latency over {len(specs)} corpus descriptions (mean {statistics.mean(words):.0f} words), "
             f"model loaded, each text new to the MiniLM cache: median {median:.1f} ms, p90 {p90:.1f} ms, "
             f"max {latencies[-1]:.1f} ms (budget 1000 ms) -> {'OK' if median < 1000 else 'OVER'}; the same texts at torch's "
             f"default of {default_threads} threads (the command line's), in the same rounds: median "
             f"{statistics.median(latency['torch default']):.1f} ms",
             f"of which MiniLM features (tokenize, run, align to words): median {statistics.median(features):.1f} ms",
             f"network part ({len(translator.nets)} members, beam {translator.cfg.beam}, MiniLM cached), rounds "
             f"interleaved: stacked encoders and decoders median {net['stacked']:.2f} ms vs member by member "
             f"{net['member by member']:.2f} ms -> {net['member by member'] / net['stacked']:.2f}x; "
             f"greedy (stacked) {net['stacked, greedy']:.2f} ms: the beam costs {net['stacked'] / net['stacked, greedy']:.2f}x"
             + (f"; without the learned findings (weight {translator.cfg.findings_cost}) {net['stacked, no findings']:.2f} ms: "
                f"the findings cost {net['stacked'] / net['stacked, no findings']:.2f}x" if "stacked, no findings" in net
                else "; the learned findings do not weigh the beam (weight 0)")]
    print("\n".join(lines))
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
