"""The README's worked example for a domain: its plain-English example, the tree the shipped
translator reads from it, and the tree `optimize` handed back from that tree in Table 2's runs.

No training here: the optimized trees are Table 2's tree-initialized DDT runs (`table2`), which
start from the example's tree; this report only gathers them, scored on the probe's scenes as
Table 2 scores every tree, so the README quotes numbers a command wrote.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from experiments.policy.table2 import JUDGED, returned_tree
from nl2policy.domains import get_domain
from nl2policy.trees.parse import parse_tree
from nl2policy.trees.render import to_text
from nl2policy.trees.tree import Tree, Vocabulary


class NoExampleRuns(ValueError):
    """Table 2 has no finished tree-DDT run that started from the domain's example tree."""


def example_runs(out: Path, domain: str, start: Tree, vocab: Vocabulary) -> list[dict]:
    """Table 2's finished tree-initialized DDT runs of `domain` whose start tree is `start`, by seed."""
    runs = []
    for path in sorted((out / domain / "runs").glob("tree_ddt_*/result.json")):
        result = json.loads(path.read_text())
        if parse_tree(result["tree"], vocab) == start and "judged_by" in result:
            runs.append(result)
    return sorted(runs, key=lambda r: r["seed"])


def returned(run: dict) -> tuple[dict, float]:
    """What `optimize` handed back in `run` (the better of the kept and polished trees by the
    scores it chose them on, as Table 2's 'returned' column) and its score on the probe's scenes."""
    which = returned_tree(run)
    return run[f"{which}_tree"], run[JUDGED[f"{which}_score"]]


def write_example(domain: str, out: Path, command: str) -> Path:
    """`out`/example_DOMAIN.md. Raises NoExampleRuns where Table 2 did not start from the example."""
    from nl2policy.language.translate import translate

    d = get_domain(domain)
    runs = example_runs(out, domain, d.example_tree, d.vocab)
    if not runs:
        raise NoExampleRuns(f"{out / domain / 'runs'} holds no finished tree-DDT run that starts from {domain}'s "
                            f"example tree (run `python -m experiments.policy table2 --domain {domain}` first)")
    reading = translate(domain, d.example)
    start_score = runs[0][JUDGED["initial_tree_score"]]
    handed = [returned(r) for r in runs]
    scores = np.array([s for _, s in handed])
    median = int(np.argsort(scores, kind="stable")[len(scores) // 2])  # the run whose returned score is the median
    tree, score = handed[median]
    seeds = ", ".join(f"seed {r['seed']}: {s:.1f}" for r, (_, s) in zip(runs, handed))
    scenes = runs[0]["judged_by"]
    lines = [
        f"# Worked example ({domain}): a description, its tree, and the tree `optimize` hands back",
        "",
        f"Made by: `{command}`  ",
        f"Optimized trees: Table 2's tree-initialized DDT runs from this tree ({len(runs)} seeds, "
        f"{runs[0]['steps']:,} PPO steps each; `table2_{domain}_runs.md`). Returns: mean over {scenes}.",
        "",
        "The description (the domain's example, `domains/" + domain + "/spec.toml`):",
        "",
        f"> {d.example}",
        "",
        "The tree it means, as the spec writes it (`example_tree`):",
        "",
        "```text",
        to_text(d.example_tree, d.vocab),
        "```",
        "",
        (f"The shipped translator reads the description as this tree (confidence {reading.confidence:.2f})."
         if reading.tree == d.example_tree else
         f"The shipped translator reads the description as another tree (confidence {reading.confidence:.2f}):\n\n"
         f"```text\n{to_text(reading.tree, d.vocab)}\n```"),
        "",
        f"Its mean return: **{start_score:.1f}**.",
        "",
        f"After `optimize` (the run with the median return of the tree handed back, seed {runs[median]['seed']}):",
        "",
        "```text",
        to_text(parse_tree(tree, d.vocab), d.vocab),
        "```",
        "",
        f"Its mean return: **{score:.1f}** (every seed: {seeds}; better than the start in "
        f"{int((scores > start_score + 1e-9).sum())} of {len(scores)}).",
        "",
    ]
    path = out / f"example_{domain}.md"
    path.write_text("\n".join(lines))
    return path
