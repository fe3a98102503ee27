"""The specification corpus: loading it with each item's writer, and splits for evaluation.

Writers matter: the product must work for people whose style it never saw, so besides plain
k-fold the splits can hold whole writers out.
"""

from __future__ import annotations

import json
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional, Sequence

from nl2policy.data import corpus_dir
from nl2policy.domains import get_domain
from nl2policy.trees import Tree, TreeError, parse_tree


@dataclass(frozen=True)
class Spec:
    """One corpus item: a writer's tree and their description of it."""

    id: str
    domain: str
    writer: str
    tree: Tree
    description: str


ROUND_FOLDERS = {1: ".", 2: "round2"}
"""Where each collection round lies in the corpus folder. Round 1: the writers' own trees
(the paper's protocol runs on it alone); round 2: trees sampled from the tree grammar, none
of them in round 1, described by four other writers."""


def load_corpus(domain: str, folder: Optional[Path] = None, rounds: Sequence[int] = (1,)) -> list[Spec]:
    """The specs of `domain` from the given collection rounds, trees validated; a bad line
    raises with its file and line."""
    unknown = sorted(set(rounds) - set(ROUND_FOLDERS))
    if unknown:
        raise ValueError(f"no collection round {unknown[0]}; rounds: {sorted(ROUND_FOLDERS)}")
    return [spec for r in rounds for spec in _load_file((folder or corpus_dir()) / ROUND_FOLDERS[r] / f"{domain}.jsonl",
                                                       domain)]


def _load_file(path: Path, domain: str) -> list[Spec]:
    vocab = get_domain(domain).vocab
    specs = []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
            tree = parse_tree(row["tree"], vocab)
            specs.append(Spec(row["id"], row["domain"], row["writer"], tree, row["description"]))
        except (json.JSONDecodeError, KeyError, TreeError) as exc:
            raise ValueError(f"{path}:{lineno}: {exc}") from exc
    return specs


def writers(specs: Sequence[Spec]) -> list[str]:
    return sorted({s.writer for s in specs})


Split = tuple[list[int], list[int]]


def kfold(specs: Sequence[Spec], k: int = 5, seed: int = 0, by_writer: bool = False) -> Iterator[Split]:
    """(train indices, test indices) for each of `k` folds.

    With ``by_writer`` the folds partition the writers, so no test writer appears in
    training (leave-writers-out); otherwise items are shuffled and dealt into folds.
    """
    rng = random.Random(seed)
    if by_writer:
        names = writers(specs)
        if k > len(names):
            raise ValueError(f"{k} writer folds asked for, but only {len(names)} writers")
        rng.shuffle(names)
        groups = [set(names[i::k]) for i in range(k)]
        fold_of = [next(i for i, g in enumerate(groups) if s.writer in g) for s in specs]
    else:
        order = list(range(len(specs)))
        rng.shuffle(order)
        fold_of = [0] * len(specs)
        for rank, idx in enumerate(order):
            fold_of[idx] = rank % k
    for fold in range(k):
        test = [i for i, f in enumerate(fold_of) if f == fold]
        train = [i for i, f in enumerate(fold_of) if f != fold]
        yield train, test
