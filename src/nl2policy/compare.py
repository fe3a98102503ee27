"""Side by side in the terminal: the most common corpus trees, the random policy, taxi's optimum."""

from __future__ import annotations

from collections import Counter
import json

from rich.console import Console
from rich.table import Table

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.policy.rollout import evaluate, random_policy, tree_policy
from nl2policy.trees import parse_tree, to_text, tree_to_json


def most_common_trees(domain: str, n: int):
    counts = Counter(json.dumps(tree_to_json(s.tree), sort_keys=True) for s in load_corpus(domain))
    vocab = get_domain(domain).vocab
    return [(parse_tree(key, vocab), c) for key, c in counts.most_common(n)]


def run_compare(console: Console, episodes: int = 10, seed: int = 0, trees_per_domain: int = 3) -> None:
    for domain in DOMAINS:
        vocab = get_domain(domain).vocab
        table = Table(title=f"{domain}: mean return over {episodes} seeded episodes (seed {seed})")
        table.add_column("policy")
        table.add_column("mean return", justify="right")
        table.add_column("± stderr", justify="right")
        ev = evaluate(domain, random_policy(domain, seed), episodes, seed)
        table.add_row("random", f"{ev.mean_return:.2f}", f"{ev.stderr:.2f}")
        for i, (tree, count) in enumerate(most_common_trees(domain, trees_per_domain), 1):
            ev = evaluate(domain, tree_policy(domain, tree), episodes, seed)
            table.add_row(f"corpus tree #{i} (written {count}x)", f"{ev.mean_return:.2f}", f"{ev.stderr:.2f}")
            console.print(f"[bold]{domain} corpus tree #{i}[/]\n{to_text(tree, vocab)}\n")
        exact = get_domain(domain).exact
        if exact is not None:
            table.add_row("optimal (value iteration, exact)", f"{exact.optimum():.2f}", "exact")
        console.print(table)
