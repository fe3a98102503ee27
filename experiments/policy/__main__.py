"""The policy lab: the paper's Table 2 (with VIPER's row), the DDT fidelity table and the corpus trees' returns.

    .venv/bin/python -m experiments.policy table2 --domain taxi --steps 300000 --tree-seeds 1 --baseline-seeds 5
    .venv/bin/python -m experiments.policy viper --domain highway --seeds 5 --out results/policy
    .venv/bin/python -m experiments.policy fidelity --states 10000 --out results/policy
    .venv/bin/python -m experiments.policy corpus-returns --domain taxi --out results/foundation
    .venv/bin/python -m experiments.policy example --domain lunar --out results/policy

Outside the product: it imports the package, the package never imports it. Each command writes
its table with the command that made it; `table2 --ray` runs its grid on Ray (``experiments.grid``).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from experiments.grid import normalize_ray_flag, ray_option_help
from nl2policy.console import CommandGroup
from nl2policy.domains import DOMAINS
from nl2policy.limits import MAX_CLI_STEPS, MAX_COUNT, MAX_EPISODES

app = typer.Typer(cls=CommandGroup, add_completion=False, no_args_is_help=True,
                  help="The policy lab: Table 2, VIPER, the fidelity table, the corpus trees' returns.")


@app.command()
def table2(
    domain: str = typer.Option(..., help="taxi or highway"),
    steps: int = typer.Option(12_000, min=1, max=MAX_CLI_STEPS, help="PPO env steps per run"),
    candidates: int = typer.Option(15, min=1, max=MAX_COUNT, help="Most frequent corpus trees to rank"),
    best: int = typer.Option(5, min=1, max=MAX_COUNT, help="Best trees (by initial return) to train"),
    select_episodes: int = typer.Option(100, min=1, max=MAX_EPISODES, help="Episodes per candidate tree when ranking"),
    tree_seeds: int = typer.Option(2, min=1, max=MAX_COUNT),
    baseline_seeds: int = typer.Option(3, min=1, max=MAX_COUNT),
    out: Path = typer.Option(Path("results/policy")),
    workers: int = typer.Option(1, min=1, max=MAX_COUNT, help="Runs side by side in forked processes on this machine"),
    ray: Optional[str] = typer.Option(None, "--ray", help=ray_option_help()),
    knob: list[str] = typer.Option([], help="KEY=VALUE: a domain knob (spec.Knobs) changed for every run, "
                                       "e.g. leaf_mass=0.9; use another --out"),
) -> None:
    """Table 2: tree-initialized DDT vs random DDT vs MLP (resumable; finished runs are skipped)."""
    import torch

    from nl2policy.console import console, domain_or_fail, fail, progress_bar
    from experiments.grid import Job, ray_failure, run_jobs
    from experiments.policy.table2 import REACH, parse_knobs, plan, run_one, select_trees, summarize, table_yardsticks
    from experiments.policy.table2_report import write_figure, write_table

    torch.set_num_threads(1)
    domain_or_fail(domain)
    try:
        knobs = parse_knobs(knob)
    except ValueError as exc:
        fail(str(exc))
    command = (f"python -m experiments.policy table2 --domain {domain} --steps {steps} --candidates {candidates} --best {best} "
               f"--select-episodes {select_episodes} --tree-seeds {tree_seeds} --baseline-seeds {baseline_seeds} --out {out}"
               + (f" --workers {workers}" if workers > 1 else "") + "".join(f" --knob {k}" for k in knob))
    root = out / domain
    selected = select_trees(domain, candidates, best, select_episodes, 0, root)
    yardsticks = table_yardsticks(domain, root)
    runs = plan(selected, tree_seeds, baseline_seeds)
    jobs = [Job(name, run_one, {"domain": domain, "method": method, "seed": seed, "steps": steps,
                                "run_dir": root / "runs" / name, "tree_json": tree_json, "knobs": knobs})
            for name, method, seed, tree_json in runs]
    finished: dict[str, dict] = {}
    with progress_bar() as bar:
        overall = bar.add_task(f"{domain}: runs" + (f" on Ray ({ray})" if ray else ""), total=len(runs))
        steps_bar: dict[str, int] = {}

        def started(job: Job) -> None:
            if ray is None and workers == 1:  # in this process: a bar of the run's steps
                steps_bar[job.name] = bar.add_task(job.name, total=steps)
                job.kwargs["progress"] = lambda n, total, t=steps_bar[job.name]: bar.update(t, completed=n)

        def record(job: Job, result: dict) -> None:
            if job.name in steps_bar:
                bar.remove_task(steps_bar.pop(job.name))
            if job.kwargs["method"] == "tree_ddt":
                result["tree_rank"] = int(job.name.split("_t")[1].split("_")[0])
            finished[job.name] = result
            bar.update(overall, completed=len(finished))
            # rewrite the table after every run, in the plan's order, so a grid cut short still
            # reports what finished and Ray's order of completion changes nothing
            results = [finished[j.name] for j in jobs if j.name in finished]
            settings = {"steps_per_run": steps, "candidates": candidates, "best": best, "select_episodes": select_episodes,
                        "tree_seeds": sorted(seed for _, method, seed, _ in runs if method == "tree_ddt"), "baseline_seeds": list(range(baseline_seeds)),
                        "finished_runs": f"{len(results)} of {len(runs)}"}
            write_table(domain, summarize(results, domain, yardsticks), results, settings, out, command)
            write_figure(domain, results, out, yardsticks, REACH)

        try:
            run_jobs(jobs, record, ray=ray, on_start=started, processes=workers)
        except Exception as exc:  # Ray's own failures are the user's to fix (an address, a dead cluster)
            reason = ray_failure(exc)
            if reason is None:
                raise
            fail(reason)
    console.print((out / f"table2_{domain}.md").read_text())


@app.command()
def viper(
    domain: str = typer.Option(..., help=f"One of: {', '.join(DOMAINS)}"),
    seeds: int = typer.Option(5, min=1, max=MAX_COUNT, help="Seeds 0..N-1: each trains its teacher as Table 2's MLP run of that seed"),
    steps: Optional[int] = typer.Option(None, min=1, max=MAX_CLI_STEPS,
                                        help="The teacher's PPO steps (default: the steps of the committed Table 2)"),
    rounds: int = typer.Option(8, min=1, max=MAX_COUNT, help="DAgger rounds"),
    steps_per_round: int = typer.Option(20_000, min=1, max=MAX_CLI_STEPS, help="Env steps of states collected a round"),
    out: Path = typer.Option(Path("results/policy")),
) -> None:
    """VIPER: a dictionary tree distilled from Table 2's MLP with DAgger (resumable), beside Table 2."""
    import json

    import torch

    from experiments.policy.viper import run_viper, write_viper_table
    from nl2policy.console import console, domain_or_fail, fail, progress_bar

    torch.set_num_threads(1)
    domain_or_fail(domain)
    if steps is None:
        table = out / f"table2_{domain}.json"
        if not table.is_file():
            fail(f"no {table} to take the MLP's steps from: give --steps")
        steps = int(json.loads(table.read_text())["settings"]["steps_per_run"])
    command = (f"python -m experiments.policy viper --domain {domain} --seeds {seeds} --steps {steps} --rounds {rounds} "
               f"--steps-per-round {steps_per_round} --out {out}")
    results = []
    with progress_bar() as bar:
        task = bar.add_task(f"{domain}: VIPER seeds", total=seeds)
        for seed in range(seeds):
            results.append(run_viper(domain, seed, steps, out / domain / "viper" / f"viper_s{seed}", rounds, steps_per_round,
                                     progress=lambda msg, s=seed: bar.console.print(f"seed {s}: {msg}", highlight=False)))
            bar.update(task, completed=seed + 1)
            write_viper_table(domain, results, out, command)
    console.print((out / f"viper_{domain}.md").read_text())


@app.command()
def example(
    domain: str = typer.Option("lunar", help=f"One of: {', '.join(DOMAINS)}"),
    out: Path = typer.Option(Path("results/policy"), help="Table 2's folder: its runs are read, example_DOMAIN.md written"),
) -> None:
    """The README's worked example: the domain's example, its translation, and Table 2's optimized trees from it."""
    from experiments.policy.example import NoExampleRuns, write_example
    from nl2policy.console import console, domain_or_fail, fail

    domain_or_fail(domain)
    try:
        path = write_example(domain, out, f"python -m experiments.policy example --domain {domain} --out {out}")
    except NoExampleRuns as exc:
        fail(str(exc))
    console.print(path.read_text(), markup=False, highlight=False, soft_wrap=True)


@app.command()
def fidelity(
    states: int = typer.Option(10_000, min=1, max=MAX_EPISODES, help="Sampled states per distribution"),
    out: Path = typer.Option(Path("results/policy")),
    domain: Optional[list[str]] = typer.Option(None, help="Only these domains (repeatable); writes fidelity_<domains>.md"),
) -> None:
    """Fresh DDT vs its tree on sampled states, for every distinct corpus tree; round trips."""
    import torch

    from nl2policy.console import console, domain_or_fail
    from nl2policy.domains import DOMAINS
    from experiments.policy.fidelity_report import write_fidelity

    torch.set_num_threads(1)
    domains = tuple(domain) if domain else DOMAINS
    for name in domains:
        domain_or_fail(name)
    command = f"python -m experiments.policy fidelity --states {states} --out {out}" + "".join(f" --domain {d}" for d in domain or [])
    console.print(write_fidelity(states, out, command, domains).read_text())


@app.command("corpus-returns")
def corpus_returns(
    domain: str = typer.Option(..., help=f"One of: {', '.join(DOMAINS)}"),
    screen_episodes: int = typer.Option(10, min=1, max=MAX_EPISODES, help="Episodes per tree when ranking all corpus trees"),
    episodes: int = typer.Option(100, min=2, max=MAX_EPISODES, help="Episodes for the final, fresh-seed measurements"),
    seed: int = typer.Option(0),
    out: Path = typer.Option(Path("results/foundation"), help="Folder for tree_returns_<domain>.md / .json"),
) -> None:
    """Mean return of random, best and median corpus tree, and taxi's optimum (results table)."""
    from experiments.policy.corpus_returns import corpus_returns as measure, write_returns_table
    from nl2policy.console import console, domain_or_fail, out_dir_or_fail, progress_bar, seed_or_fail

    domain_or_fail(domain)
    seed_or_fail(seed)
    out_dir_or_fail(out)
    with progress_bar() as bar:
        task = bar.add_task(f"{domain}: screening corpus trees", total=None)
        rows = measure(domain, screen_episodes, episodes, seed, progress=lambda i, n: bar.update(task, completed=i, total=n))
    command = (f"python -m experiments.policy corpus-returns --domain {domain} --screen-episodes {screen_episodes} "
               f"--episodes {episodes} --seed {seed} --out {out}")
    console.print(write_returns_table(domain, rows, out, command).read_text())


def main() -> None:
    from nl2policy import console as terminal

    terminal.owns_process = True
    app(args=normalize_ray_flag(sys.argv[1:]))


if __name__ == "__main__":
    main()
