"""The main job, end to end in the terminal: description -> tree -> PPO -> readable tree.

``nl2policy run --domain D "TEXT"`` translates the text (training the default translator
first if there is none), shows the tree with its confidence, improves it with PPO from the
tree-initialized DDT, and shows the tree before and after with their returns.
"""

from __future__ import annotations

import json
from pathlib import Path

from rich.console import Console
from rich.panel import Panel
from rich.table import Table

from nl2policy.domains import get_domain
from nl2policy.trees import Tree, TreeError, parse_tree, to_text

def show_tree(console: Console, title: str, tree_json: dict, domain: str) -> None:
    vocab = get_domain(domain).vocab
    try:
        body = to_text(parse_tree(tree_json, vocab), vocab)
    except TreeError:  # a learned raw threshold test that no question of the domain matches
        body = json.dumps(tree_json, indent=2)
    console.print(Panel(body, title=title, expand=False))


def run_pipeline(console: Console, err: Console, domain: str, text: str, steps: int, seed: int, out: Path) -> dict:
    from nl2policy.console import fail, progress_bar
    from nl2policy.language.translate import EmptyDescription, translate
    from nl2policy.limits import trained_steps
    from nl2policy.policy.optimize import OptimizeRefused, optimize_tree

    console.print(Panel(text, title=f"description ({domain})", expand=False))
    try:
        translation = translate(domain, text)
    except EmptyDescription as exc:
        fail(str(exc))
    tree: Tree = translation.tree
    show_tree(console, f"translated tree · confidence {translation.confidence:.0%}", json.loads(json.dumps(translation.to_json()["tree"])), domain)
    for warning in translation.warnings:
        err.print(f"[yellow]warning:[/] {warning}")
    if translation.questions:  # unsure: what it would ask, and where to answer (PPO starts from this tree meanwhile)
        err.print(f"[yellow]unsure:[/] the translator asks: {translation.questions[0].text}\n"
                  f"  Answer its questions with `nl2policy translate --domain {domain} --interactive \"...\"` or on the "
                  "Specify page, then optimize the tree you get.", highlight=False)
    with progress_bar() as bar:
        task = bar.add_task(f"{domain}: PPO from the tree", total=trained_steps(domain, steps))
        try:
            summary = optimize_tree(domain, tree, steps, seed, out, progress=lambda n, total: bar.update(task, completed=n))
        except OptimizeRefused as exc:  # --out holds another tree's checkpoint
            fail(str(exc))
    final = json.loads((out / "final_tree.json").read_text())
    show_tree(console, f"after PPO (returned: {summary['returned']})", final, domain)
    table = Table(title=f"mean return over {summary['eval_episodes']} evaluation episodes")
    table.add_column("policy")
    table.add_column("mean return", justify="right")
    table.add_row("translated tree", f"{summary['initial_mean_return']:.2f}")
    table.add_row("trained DDT (soft)", f"{summary['final_soft_ddt_return']:.2f}")
    read = summary["keep_best"].get("last_checkpoint_read", "rounded")
    table.add_row(f"PPO's last tree ({read})", f"{summary['last_tree_mean_return']:.2f}")
    table.add_row(f"kept tree, before polish ({summary['keep_best']['kept']})", f"{summary['kept_mean_return']:.2f}")
    table.add_row(f"returned tree ({summary['returned']})", f"{summary['final_mean_return']:.2f}")
    exact = get_domain(domain).exact
    if exact is not None:
        table.add_row("optimal (value iteration)", f"{exact.optimum():.2f}")
    console.print(table)
    console.print(f"files in {out}: initial_tree.json, final_tree.json (returned), last_tree.json, best_tree.json, "
                  "curve.csv, curve.png, summary.json")
    return summary
