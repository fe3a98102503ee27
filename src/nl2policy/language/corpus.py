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
from nl2policy.trees import Tree, TreeError, parse_tree, tree_to_json


@dataclass(frozen=True)
class Spec:
    """One corpus item: a writer's tree and their description of it."""

    id: str
    domain: str
    writer: str
    tree: Tree
    description: str
    round: int = 1  # the collection round (ROUND_FOLDERS)


ROUND_FOLDERS = {1: ".", 2: "round2"}
"""Where each collection round lies in the corpus folder. Round 1: the writers' own trees
(the paper's protocol runs on it alone); round 2: trees sampled from the tree grammar, none
of them in round 1, described by four other writers."""


def load_corpus(domain: str, folder: Optional[Path] = None, rounds: Sequence[int] = (1,)) -> list[Spec]:
    """The specs of `domain` from the given collection rounds, trees validated; a bad line
    raises with its file and line. A domain the corpus does not cover (its vocabulary.json
    does not name it: nobody has described it yet, as lunar) has none; a covered domain's
    missing file is an error."""
    unknown = sorted(set(rounds) - set(ROUND_FOLDERS))
    if unknown:
        raise ValueError(f"no collection round {unknown[0]}; rounds: {sorted(ROUND_FOLDERS)}")
    folder = folder or corpus_dir()
    if domain not in covered_domains(folder):
        get_domain(domain)  # an unknown domain is still a KeyError
        return []
    return [spec for r in rounds for spec in _load_file(folder / ROUND_FOLDERS[r] / f"{domain}.jsonl", domain, r)]


def covered_domains(folder: Optional[Path] = None) -> set[str]:
    """The domains a corpus folder has descriptions of: those its vocabulary.json names."""
    vocabulary = json.loads(((folder or corpus_dir()) / "vocabulary.json").read_text())
    return {k for k, v in vocabulary.items() if isinstance(v, dict) and "questions" in v}


def _load_file(path: Path, domain: str, round_: int = 1) -> list[Spec]:
    vocab = get_domain(domain).vocab.dictionary_only()  # a described tree asks dictionary questions only
    specs = []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
            tree = parse_tree(row["tree"], vocab)
            specs.append(Spec(row["id"], row["domain"], row["writer"], tree, row["description"], round_))
        except (json.JSONDecodeError, KeyError, TreeError) as exc:
            raise ValueError(f"{path}:{lineno}: {exc}") from exc
    return specs


def writers(specs: Sequence[Spec]) -> list[str]:
    return sorted({s.writer for s in specs})


Split = tuple[list[int], list[int]]


def policy_key(domain: str, tree: Tree) -> tuple[str, ...]:
    """What a tree does in every situation the world can produce (its action for each possible
    answer set): two trees with the same key are the same policy, however they are drawn."""
    d = get_domain(domain)
    return tuple(tree.act(answers) for answers in d.possible_answer_sets)


def new_writer_folds(specs: Sequence[Spec]) -> Iterator[Split]:
    """One fold per writer of round 2: that writer's specs are the test set, and training is
    every other spec whose policy none of them has. The test writer is new and so are the test
    trees: the case of a real user, which neither leave-writers-out (round 1's writers share
    trees) nor leave-trees-out (the writers are seen) measures alone."""
    for writer in writers([s for s in specs if s.round == 2]):
        test = [i for i, s in enumerate(specs) if s.writer == writer]
        held = {policy_key(specs[i].domain, specs[i].tree) for i in test}
        train = [i for i, s in enumerate(specs) if s.writer != writer and policy_key(s.domain, s.tree) not in held]
        yield train, test


def kfold(specs: Sequence[Spec], k: int = 5, seed: int = 0, by_writer: bool = False,
          by_tree: bool = False) -> Iterator[Split]:
    """(train indices, test indices) for each of `k` folds.

    With ``by_writer`` the folds partition the writers, so no test writer appears in
    training (leave-writers-out). With ``by_tree`` they partition the policies (``policy_key``),
    so no test spec's policy appears in training, however its tree is drawn (leave-trees-out:
    the translator must compose a tree it never saw). Otherwise items are shuffled and dealt
    into folds.
    """
    if by_writer and by_tree:
        raise ValueError("hold out writers or trees, not both")
    rng = random.Random(seed)
    if by_tree:
        keys = [policy_key(s.domain, s.tree) for s in specs]
        distinct = sorted(set(keys))
        if k > len(distinct):
            raise ValueError(f"{k} tree folds asked for, but only {len(distinct)} distinct policies")
        rng.shuffle(distinct)
        # Deal the policies, largest group first, each to the fold with the fewest specs so far,
        # so the folds are near equal in specs although groups differ in size.
        size = {key: keys.count(key) for key in distinct}
        fold_size, fold_of_key = [0] * k, {}
        for key in sorted(distinct, key=lambda key: -size[key]):
            fold = min(range(k), key=lambda f: fold_size[f])
            fold_of_key[key] = fold
            fold_size[fold] += size[key]
        fold_of = [fold_of_key[key] for key in keys]
    elif by_writer:
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


def distinct_trees(domain: str) -> list[Tree]:
    """Each distinct tree of `domain`'s round-1 corpus once, in the corpus's order (spellings, not policies)."""
    seen: dict[str, Tree] = {}
    for spec in load_corpus(domain):
        seen.setdefault(json.dumps(tree_to_json(spec.tree), sort_keys=True), spec.tree)
    return list(seen.values())
