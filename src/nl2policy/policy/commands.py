"""CLI commands of the policy area: ``optimize`` and ``ceilings``. The policy lab (Table 2, the
fidelity table, the corpus returns) is ``python -m experiments.policy``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from nl2policy.domains import DOMAINS
from nl2policy.limits import MAX_CLI_STEPS, MAX_EPISODES


def register(app: typer.Typer) -> None:
    app.command("optimize")(optimize)
    app.command("ceilings")(ceilings)


def optimize(
    domain: str = typer.Option(..., help=f"One of: {', '.join(DOMAINS)}"),
    tree: str = typer.Option(..., help="A tree as inline JSON or a path to a JSON file"),
    steps: int = typer.Option(20_000, max=MAX_CLI_STEPS, help="PPO env steps (whole rollouts: rounded up to a multiple of 512 for taxi, "
                                           "4,096 for highway on its twin, 256 on highway-env)"),
    seed: int = typer.Option(0),
    out: Path = typer.Option(Path("runs/optimize"), help="Output folder; holding a checkpoint, the run resumes"),
    eval_episodes: Optional[int] = typer.Option(None, min=1, max=MAX_EPISODES, help="Episodes for the before/after returns (default: the domain's eval_episodes, domains/<name>/spec.toml)"),
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
    learned = "; a learned threshold, in the domain's units" if summary["final_tree_has_raw_tests"] else ""
    console.print(f"[bold]after[/] ({summary['returned']}{learned})\n" + to_text(parse_tree(final, d.vocab), d.vocab))
    print(json.dumps(summary))


def ceilings(
    domain: str = typer.Option(..., help="A domain whose folder has an exact ceiling search (taxi), or a fast simulator to climb on"),
    max_depth: int = typer.Option(3, min=1, max=3, help="Deepest dictionary trees to search (the grid allows 3)"),
    out: Path = typer.Option(Path("results/policy"), help="Folder for ceilings_<domain>.md / .json"),
) -> None:
    """The domain's yardsticks: by exact search where its folder has one (optimum, best stationary
    feature policy, best trees), else a lower bound by the sampled climb from several starts."""
    from nl2policy.console import console, domain_or_fail, fail, out_dir_or_fail, progress_bar

    from nl2policy.policy import ceiling_climb
    from nl2policy.policy.polish import can_polish

    d = domain_or_fail(domain)
    if d.ceilings is None and (d.exact is not None or not can_polish(domain)):
        fail(f"{domain} has no ceiling search (its spec.toml names no `ceilings` module) and no fast simulator to climb on")
    search = d.module(d.ceilings) if d.ceilings is not None else ceiling_climb
    out_dir_or_fail(out)
    command = f"nl2policy ceilings --domain {domain} --max-depth {max_depth} --out {out}"
    with progress_bar() as bar:
        task = bar.add_task(f"{domain}: ceilings", total=None)
        try:
            result = search.compute_ceilings(domain, max_depth, progress=lambda text: bar.update(task, description=text))
        except ValueError as exc:
            fail(str(exc))
    console.print(search.write_ceilings(result, out, command).read_text())
