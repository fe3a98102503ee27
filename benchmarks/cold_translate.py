"""How long a cold ``nl2policy translate --domain taxi "..."`` takes beside ``nl2policy --help``
(issue 29's budget: a median under 2.5 s), and where its time goes.

Each timing is a fresh process, as a user runs the command; the two commands alternate, so a
busy machine slows both alike, and the ratio of their medians is measured side by side in this
one run. Peak memory is the child's own maximum resident set (wait4). The first translation in a
new NL2POLICY_HOME builds MiniLM's saved int8 trace (once per machine); it is timed separately,
and the cold runs after it read the saved file, as every later translation does.

With ``--compare-with REV`` the same translation is also timed, in the same alternation, with the
package as it was at git revision REV (its ``src`` extracted with ``git archive`` to a temporary
folder and run through ``python -m nl2policy.cli`` with that folder first on PYTHONPATH).

Run: .venv/bin/python benchmarks/cold_translate.py [--runs 7] [--compare-with REV] [--out results/benchmarks/cold_translate.txt]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TEXT = "If I have a passenger I drive to the airport; if not, I go to the city unless the traffic is heavy."
CLI = [str(Path(sys.executable).parent / "nl2policy")]  # the installed executable, as a user runs it
PHASES = """
import time
t0 = time.perf_counter()
import nl2policy.cli
t1 = time.perf_counter()
from nl2policy.language import translate as tr
import torch
if THREADS_HERE:
    torch.set_num_threads(THREADS_HERE)  # 1: as the translate command does
t2 = time.perf_counter()
tr.get_model("taxi")
t3 = time.perf_counter()
from nl2policy.language.models import pretrained
pretrained.saved_forward(6); pretrained.fast_tokenizer()
t4 = time.perf_counter()
tr.translate("taxi", TEXT_HERE)
t5 = time.perf_counter()
for name, a, b in [("import the CLI (typer, rich, domains)", t0, t1), ("import the translator's modules (torch, ...)", t1, t2),
                   ("load the translator's networks", t2, t3), ("load MiniLM's saved trace and tokenizer", t3, t4),
                   ("translate (MiniLM, decoder, checks)", t4, t5)]:
    print(f"{b - a:7.2f} s  {name}")
"""


def timed(cmd: list[str], env: dict) -> tuple[float, float, float]:
    """(wall seconds, peak RSS MiB, CPU seconds) of one fresh process."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(cmd[:5])} failed: {proc.stderr.read().decode()[-500:]}")
    proc.stderr.close()
    return wall, usage.ru_maxrss / 1024, usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--out", default=None, help="Also write the report to this file")
    parser.add_argument("--compare-with", default=None, help="A git revision whose translate is timed alongside")
    args = parser.parse_args()
    home = Path(tempfile.mkdtemp(prefix="nl2policy-bench-"))
    env = {**os.environ, "NL2POLICY_HOME": str(home)}
    translate = CLI + ["translate", "--domain", "taxi", TEXT]
    help_cmd = CLI + ["--help"]
    commands = {"help": (help_cmd, env), "translate": (translate, env)}
    if args.compare_with:
        old_src = home / "old"
        old_src.mkdir()
        archive = subprocess.run(["git", "archive", args.compare_with, "src"], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(old_src)], input=archive, check=True)
        old_env = {**env, "PYTHONPATH": str(old_src / "src")}
        commands[f"translate at {args.compare_with}"] = ([sys.executable, "-m", "nl2policy.cli"] + translate[1:], old_env)
    try:
        first, first_mib, _ = timed(translate, env)  # builds the saved MiniLM trace in this fresh home
        times: dict[str, list[tuple[float, float, float]]] = {name: [] for name in commands}
        load_before = os.getloadavg()[0]
        for _ in range(args.runs):
            for name, (cmd, cmd_env) in commands.items():
                times[name].append(timed(cmd, cmd_env))
        phases = {threads: subprocess.run([sys.executable, "-c", PHASES.replace("TEXT_HERE", repr(TEXT + " (phases)"))
                                           .replace("THREADS_HERE", str(threads))], env=env,
                                          capture_output=True, text=True, check=True).stdout
                  for threads in (1, 0)}
    finally:
        shutil.rmtree(home, ignore_errors=True)
    med = {k: statistics.median(w for w, _, _ in v) for k, v in times.items()}
    mib = {k: statistics.median(m for _, m, _ in v) for k, v in times.items()}
    cpu = {k: statistics.median(c for _, _, c in v) for k, v in times.items()}
    lines = [
        "# Cold translate beside --help",
        "",
        f"command: .venv/bin/python benchmarks/cold_translate.py --runs {args.runs}"
        + (f" --compare-with {args.compare_with}" if args.compare_with else "") + (f" --out {args.out}" if args.out else ""),
        f"machine: {os.cpu_count()} CPUs; 1-minute load average {load_before:.2f} before the timed runs, "
        f"{os.getloadavg()[0]:.2f} after (other work on the machine slows every command alike)",
        f"text: {TEXT!r}",
        "",
        f"runs: {args.runs} of each, alternating, each a fresh process",
        *[f"{name:<28} median {med[name]:5.2f} s   CPU {cpu[name]:5.2f} s   peak RSS {mib[name]:4.0f} MiB   "
          f"(all: {', '.join(f'{w:.2f}' for w, _, _ in times[name])})" for name in times],
        *[f"ratio {name} / help (medians): {med[name] / med['help']:.1f}x" for name in times if name != "help"],
        f"budget: median cold translate under 2.5 s: {'met' if med['translate'] < 2.5 else 'NOT met'}",
        "",
        f"first translate in a new data folder (builds MiniLM's saved trace, once): {first:.2f} s, peak RSS {first_mib:.0f} MiB",
        "",
        "where a cold translate's time goes (one fresh process, phases timed inside it), on one torch thread as",
        "the translate command runs:",
        phases[1].rstrip(),
        "",
        f"the same at torch's default of {os.cpu_count()} threads (another fresh process), for comparison:",
        phases[0].rstrip(),
    ]
    report = "\n".join(lines) + "\n"
    print(report)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(report)


if __name__ == "__main__":
    main()
