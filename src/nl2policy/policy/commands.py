"""CLI commands of the policy area: ``optimize``, ``policy-experiment``, ``policy-fidelity``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from nl2policy.grid import ray_option_help
from nl2policy.limits import MAX_CLI_STEPS, MAX_COUNT, MAX_EPISODES


def register(app: typer.Typer) -> None:
    app.command("optimize")(optimize)
    app.command("policy-experiment")(policy_experiment)
    app.command("policy-fidelity")(policy_fidelity)
    app.command("ceilings")(ceilings)


def optimize(
    domain: str = typer.Option(..., help="taxi or highway"),
    tree: str = typer.Option(..., help="A tree as inline JSON or a path to a JSON file"),
    steps: int = typer.Option(20_000, max=MAX_CLI_STEPS, help="PPO env steps (whole rollouts: rounded up to a multiple of 512 for taxi, "
                                           "4,096 for highway on its twin, 256 on highway-env)"),
    seed: int = typer.Option(0),
    out: Path = typer.Option(Path("runs/optimize"), help="Output folder; holding a checkpoint, the run resumes"),
    eval_episodes: Optional[int] = typer.Option(None, min=1, max=MAX_EPISODES, help="Episodes for the before/after returns (default: the domain's eval_episodes, domains/<name>.toml)"),
    polish: Optional[bool] = typer.Option(None, "--polish/--no-polish", help="Hill-climb the kept tree over questions and actions: on the exact model (taxi), or on common sampled scenes of the fast simulator (highway); default on where the domain has either"),
    simulator: str = typer.Option("fast", help="Train on the domain's fast simulator (highway: the vectorized twin) or on its reference env (highway-env); returns are always the reference env's"),
) -> None:
    """Improve a tree with PPO (tree -> DDT -> PPO -> tree), never returning a worse tree; writes trees, curve and summary.json."""
    import torch

    from nl2policy.console import (console, domain_or_fail, fail, out_dir_or_fail, progress_bar, seed_or_fail,
                                   steps_or_fail, tree_or_fail)
    from nl2policy.policy.optimize import OptimizeRefused, optimize_tree
    from nl2policy.policy.sb3_policy import SIMULATORS
    from nl2policy.trees import parse_tree, to_text

    torch.set_num_threads(1)
    d = domain_or_fail(domain)
    parsed = tree_or_fail(domain, tree)
    seed_or_fail(seed)
    if simulator not in SIMULATORS:
        fail(f"--simulator must be one of {', '.join(SIMULATORS)}, not {simulator!r}")
    total = steps_or_fail(domain, steps, simulator=simulator)
    out_dir_or_fail(out)
    with progress_bar() as bar:
        task = bar.add_task(f"{domain}: PPO steps", total=total)
        try:
            summary = optimize_tree(domain, parsed, steps, seed, out, eval_episodes=eval_episodes, polish=polish,
                                    simulator=simulator, progress=lambda n, total: bar.update(task, completed=n))
        except OptimizeRefused as exc:
            fail(str(exc))
    console.print("[bold]before[/]\n" + to_text(parsed, d.vocab))
    final = json.loads((out / "final_tree.json").read_text())
    if summary["final_tree_has_raw_tests"]:
        console.print(f"[bold]after[/] ({summary['returned']}; has raw threshold tests)\n" + json.dumps(final, indent=2))
    else:
        console.print(f"[bold]after[/] ({summary['returned']})\n" + to_text(parse_tree(final, d.vocab), d.vocab))
    print(json.dumps(summary))


def policy_experiment(
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
) -> None:
    """Table 2: tree-initialized DDT vs random DDT vs MLP (resumable; finished runs are skipped)."""
    import torch

    from nl2policy.console import console, domain_or_fail, fail, progress_bar
    from nl2policy.grid import Job, ray_failure, run_jobs
    from nl2policy.policy.experiment import REACH, plan, run_one, select_trees, summarize, table_yardsticks
    from nl2policy.policy.experiment_report import write_figure, write_table

    torch.set_num_threads(1)
    domain_or_fail(domain)
    command = (f"nl2policy policy-experiment --domain {domain} --steps {steps} --candidates {candidates} --best {best} "
               f"--select-episodes {select_episodes} --tree-seeds {tree_seeds} --baseline-seeds {baseline_seeds} --out {out}"
               + (f" --workers {workers}" if workers > 1 else ""))
    root = out / domain
    selected = select_trees(domain, candidates, best, select_episodes, 0, root)
    yardsticks = table_yardsticks(domain, root)
    runs = plan(selected, tree_seeds, baseline_seeds)
    jobs = [Job(name, run_one, {"domain": domain, "method": method, "seed": seed, "steps": steps,
                                "run_dir": root / "runs" / name, "tree_json": tree_json})
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


def policy_fidelity(
    states: int = typer.Option(10_000, min=1, max=MAX_EPISODES, help="Sampled states per distribution"),
    out: Path = typer.Option(Path("results/policy")),
    domain: Optional[list[str]] = typer.Option(None, help="Only these domains (repeatable); writes fidelity_<domains>.md"),
) -> None:
    """Fresh DDT vs its tree on sampled states, for every distinct corpus tree; round trips."""
    import torch

    from nl2policy.console import console, domain_or_fail
    from nl2policy.domains import DOMAINS
    from nl2policy.policy.fidelity_report import write_fidelity

    torch.set_num_threads(1)
    domains = tuple(domain) if domain else DOMAINS
    for name in domains:
        domain_or_fail(name)
    command = f"nl2policy policy-fidelity --states {states} --out {out}" + "".join(f" --domain {d}" for d in domain or [])
    console.print(write_fidelity(states, out, command, domains).read_text())


def ceilings(
    domain: str = typer.Option(..., help="A domain with an exact model (taxi)"),
    max_depth: int = typer.Option(3, min=1, max=3, help="Deepest dictionary trees to search (the grid allows 3)"),
    out: Path = typer.Option(Path("results/policy"), help="Folder for ceilings_<domain>.md / .json"),
) -> None:
    """The domain's yardsticks by exact search: optimum, best stationary feature policy, best trees."""
    from nl2policy.console import console, domain_or_fail, fail, out_dir_or_fail, progress_bar
    from nl2policy.policy.ceilings_report import compute_ceilings, write_ceilings

    domain_or_fail(domain)
    out_dir_or_fail(out)
    command = f"nl2policy ceilings --domain {domain} --max-depth {max_depth} --out {out}"
    with progress_bar() as bar:
        task = bar.add_task(f"{domain}: ceilings", total=None)
        try:
            result = compute_ceilings(domain, max_depth, progress=lambda text: bar.update(task, description=text))
        except ValueError as exc:
            fail(str(exc))
    console.print(write_ceilings(result, out, command).read_text())
