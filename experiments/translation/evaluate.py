"""The translation experiment: k-fold cross-validation (repeated) and leave-writers-out, per
domain and model, with exact-tree, token-wise (grid slot) and policy accuracy.

Augmentation and synthetic data are built inside each fold from its training indices only.
Each finished fold is appended to `runs.jsonl`, so an interrupted experiment resumes where it
stopped; `summary.summarize` turns them into the Markdown/JSON tables and the figure.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path
from typing import Callable, Optional, Sequence

import torch

from nl2policy.domains import get_domain
from experiments.grid import Job, run_jobs
from nl2policy.language.corpus import Spec, kfold, load_corpus, new_writer_folds, policy_key
from nl2policy.language.dataset import member_pairs
from nl2policy.language.models.config import MODELS, ModelConfig, networks_config
from nl2policy.language.models.pretrained import MiniLMCache
from nl2policy.language.findings import FindingsModel, train_findings
from nl2policy.language.train import fit
from nl2policy.language.translator import TrainedTranslator
from nl2policy.language.translate import LOW_CONFIDENCE, tree_probability
from nl2policy.trees import GRID_SLOTS, Tree, TreeError, to_grid, to_tokens
from nl2policy.trees.parse import validate

# decoding choices a fold also scores dialled down to a smaller value (same trained networks) when
# the config sets more: record key -> (TrainedTranslator and ModelConfig attribute, that value,
# label in the summary)
DECODING_ALTERNATIVES = {"greedy_tree_acc": ("beam", 1, "greedy (beam of 1)"),
                         "first_3_members_tree_acc": ("ensemble", 3, "its first 3 members"),
                         "no_findings_tree_acc": ("findings_cost", 0.0, "no learned findings"),
                         "summed_score_tree_acc": ("length_norm", 0.0, "trees ranked by summed log-probability")}


def slot_accuracy(pred: Tree, gold: Tree) -> float:
    """Token-wise accuracy on the 15-slot grid: slots filled in either tree that agree."""
    a, b = to_grid(pred), to_grid(gold)
    used = [i for i in range(GRID_SLOTS) if a[i] is not None or b[i] is not None]
    return sum(a[i] == b[i] for i in used) / len(used)


def score(domain: str, preds: Sequence[Tree], golds: Sequence[Tree]) -> dict:
    d = get_domain(domain)
    valid = 0
    for p in preds:
        try:
            validate(p, d.vocab)
            valid += 1
        except TreeError:
            pass
    n = len(golds)
    return {"n": n, "valid": valid,
            "tree_acc": sum(p == g for p, g in zip(preds, golds)) / n,
            "token_acc": sum(slot_accuracy(p, g) for p, g in zip(preds, golds)) / n,
            "policy_acc": sum(d.same_policy(p, g) for p, g in zip(preds, golds)) / n}


def unseen_trees(specs: Sequence[Spec], train_idx: Sequence[int], test_idx: Sequence[int]) -> list[bool]:
    """For each test description: is its tree absent from every training description? Such a
    tree has to be composed from parts seen elsewhere, which is where translators fail most."""
    seen = {tuple(to_tokens(specs[i].tree)) for i in train_idx}
    return [tuple(to_tokens(specs[i].tree)) not in seen for i in test_idx]


def run_fold(domain: str, specs: Sequence[Spec], train_idx: Sequence[int], test_idx: Sequence[int], name: str,
             seed: int, cache: MiniLMCache, workers: int = 1, keep: Optional[Path] = None,
             reuse: Optional[dict] = None, hold_test_trees: bool = False) -> dict:
    """Train `name` on one fold and score it on the held-out descriptions. `keep`: also save the
    fold's networks there (with their word vocabulary and the fold's indices), so decoding
    choices can be studied on them later without retraining. `reuse`: such a saved fold (same
    fold, a model with the same training: `kept_networks`), decoded instead of training anew.
    `hold_test_trees`: no synthetic pair has a test description's policy (the protocols of
    unseen trees: a random tree that happens to be a test tree would be a tree training saw)."""
    start = time.time()
    cfg = MODELS[name]
    held = {policy_key(domain, specs[i].tree) for i in test_idx} if hold_test_trees else set()
    pairs = member_pairs(domain, specs, train_idx, cfg, exclude=lambda tree: policy_key(domain, tree) in held)
    if reuse is not None:
        model = TrainedTranslator.from_states(domain, name, cfg, reuse["words"], reuse["nets"][:cfg.ensemble], cache)
        if reuse.get("findings") is not None:  # the findings trained with these networks
            model.findings = FindingsModel.from_state(reuse["findings"], cache)
    else:
        model = fit(domain, name, cfg, pairs, seed, cache=cache,
                    vocab_texts=[specs[i].description for i in train_idx], workers=workers)
    if cfg.findings_cost and model.findings is None:  # decoding kept networks: their findings train here
        model.findings = train_findings(domain, pairs(0) if callable(pairs) else pairs, seed + cfg.seed_offset, cache)
    if keep is not None:
        keep.parent.mkdir(parents=True, exist_ok=True)
        torch.save({"domain": domain, "name": name, "cfg": model.cfg.to_dict(),
                    "words": model.words.itos[2:], "machine": machine(),
                    "nets": [net.state_dict() for net in model.nets], "train": list(train_idx), "test": list(test_idx),
                    "findings": model.findings.state() if model.findings is not None else None}, keep)
    texts = [specs[i].description for i in test_idx]
    decoded = model.predict(texts)
    preds = [t for t, _ in decoded]
    golds = [specs[i].tree for i in test_idx]
    result = score(domain, preds, golds)
    # calibration: is "confident" (the product of node probabilities, what translate() reports
    # for an on-topic text, at or above its warning threshold) more often right than "unsure"?
    sure = [tree_probability(probs) >= LOW_CONFIDENCE for _, probs in decoded]
    right = [p == g for p, g in zip(preds, golds)]
    result.update(confident=sum(sure), confident_right=sum(s and r for s, r in zip(sure, right)),
                  unsure_right=sum(r and not s for s, r in zip(sure, right)))
    # each translation's confidence and whether it was right, for the reliability table (summary.py)
    result["confidence"] = [[specs[i].id, round(tree_probability(probs), 4), r]
                            for i, (_, probs), r in zip(test_idx, decoded, right)]
    unseen = unseen_trees(specs, train_idx, test_idx)
    result.update(unseen=sum(unseen), unseen_right=sum(u and r for u, r in zip(unseen, right)))
    # what went wrong, for error analysis without retraining: (spec id, the predicted tree's tokens)
    result["errors"] = [[specs[i].id, " ".join(to_tokens(p))] for i, p, r in zip(test_idx, preds, right) if not r]
    # every translation (spec id, predicted tokens), for tables by tree size and the clarify probe
    result["predictions"] = [[specs[i].id, " ".join(to_tokens(p))] for i, p in zip(test_idx, preds)]
    # the same networks on the same fold, decoded with less of each decoding choice the config makes
    for key, (attr, off, _) in DECODING_ALTERNATIVES.items():
        if getattr(model.cfg, attr, off) > off:  # (a setting of deleted variants: only in older records)
            setattr(model, attr, off)
            result[key] = score(domain, [t for t, _ in model.predict(texts)], golds)["tree_acc"]
            setattr(model, attr, None)  # back to the config's
    result.update(train_pairs=len(pairs(0) if callable(pairs) else pairs), seconds=round(time.time() - start, 1),
                  synthetic_holds_test_trees=hold_test_trees)
    return result


def machine() -> str:
    """The kind of CPU a fold trained on, recorded with it. A fold retrains bit for bit on the
    same kind of CPU, not across kinds: the float kernels PyTorch picks depend on the
    instruction set (AVX-512 or not), and 30 epochs turn a last-bit difference into other
    networks, a few trees apart on a 40-description fold."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor() or platform.machine()
    model = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")), "")
    flags = next((line.split(":", 1)[1].split() for line in info.splitlines() if line.startswith("flags")), [])
    return f"{model or platform.machine()}, {'avx512' if 'avx512f' in flags else 'no avx512'}"


HELD_TREE_PROTOCOLS = ("trees", "new")
"""The protocols whose test trees training must never see, synthetic pairs included."""

PROTOCOL_ROUNDS = {"cv": (1,), "writers": (1,), "trees": (1, 2), "new": (1, 2), "cvboth": (1, 2), "writersboth": (1, 2)}
"""The corpus rounds each protocol runs on: the paper's protocol and leave-writers-out on round
1, as before; leave-trees-out and new writers with new trees on both rounds (round 2's trees
are all new to round 1); cvboth and writersboth test on round 1's folds of cv and writers, with
every round-2 spec joining each training fold (the shipped model trains on both rounds)."""


def fold_count(protocol: str, repeats: int) -> int:
    """Folds a protocol runs: 5 per repeat (cv, trees), 4 writer folds (writers, new)."""
    return 5 * repeats if protocol in ("cv", "trees", "cvboth") else 4


def plan_folds(specs: Sequence[Spec], protocol: str, repeats: int) -> list[tuple[str, list[int], list[int]]]:
    """(fold key, train, test). "cv": 5 folds x `repeats` (fold seed = repeat); "writers":
    4 folds of 2 held-out writers each; "trees": 5 folds x `repeats` of held-out policies; "new":
    one fold per round-2 writer, whose specs' policies training never has (new_writer_folds)."""
    if protocol == "cv":
        return [(f"cv-r{r}-f{f}", tr, te) for r in range(repeats) for f, (tr, te) in enumerate(kfold(specs, 5, seed=r))]
    if protocol == "trees":
        return [(f"trees-r{r}-f{f}", tr, te) for r in range(repeats)
                for f, (tr, te) in enumerate(kfold(specs, 5, seed=r, by_tree=True))]
    if protocol == "new":
        return [(f"new-f{f}", tr, te) for f, (tr, te) in enumerate(new_writer_folds(specs))]
    if protocol in ("cvboth", "writersboth"):  # round 1's own folds, round 2 added to every training fold
        first = [i for i, s in enumerate(specs) if s.round == 1]
        extra = [i for i, s in enumerate(specs) if s.round != 1]
        own = plan_folds([specs[i] for i in first], protocol[:-len("both")], repeats)
        return [(protocol + key[key.index("-"):], [first[i] for i in tr] + extra, [first[i] for i in te])
                for key, tr, te in own]
    return [(f"writers-f{f}", tr, te) for f, (tr, te) in enumerate(kfold(specs, 4, seed=0, by_writer=True))]


_CACHES: dict[str, MiniLMCache] = {}
"""MiniLM states per domain, kept by the process across the folds it runs (a cache: same results)."""


def fold_job(domain: str, name: str, protocol: str, repeats: int, key: str, workers: int = 1,
             keep_networks: Optional[Path] = None, networks_from: Optional[Path] = None) -> dict:
    """One fold of the grid, from its coordinates alone (the fold's indices are recomputed), so
    that any process, here or a Ray worker, gives the same result: run_fold plus the fold's record."""
    torch.set_num_threads(1)
    specs = load_corpus(domain, rounds=PROTOCOL_ROUNDS[protocol])
    tr, te = next((tr, te) for k, tr, te in plan_folds(specs, protocol, repeats) if k == key)
    seed = int(key.split("-r")[1][0]) if "-r" in key else 0
    keep = keep_networks / f"{domain}-{name}-{key}.pt" if keep_networks else None
    reuse = kept_networks(networks_from, domain, name, key, tr, te) if networks_from else None
    cache = _CACHES.setdefault(domain, MiniLMCache())
    result = run_fold(domain, specs, tr, te, name, seed, cache, workers, keep, reuse,
                      hold_test_trees=protocol in HELD_TREE_PROTOCOLS)
    result.update(domain=domain, model=name, fold=key, protocol=protocol, workers=workers,
                  machine=reuse["machine"] if reuse else machine())
    if reuse:
        result["networks_from"] = reuse["name"]
    return result


class UnknownFold(ValueError):
    """A fold key asked for (--fold) that the plan does not have."""


def run_experiment(plan: Sequence[tuple[str, str, str, int]], out: Path,
                   progress: Optional[Callable[[str], None]] = None, workers: int = 1,
                   keep_networks: Optional[Path] = None, networks_from: Optional[Path] = None,
                   ray: Optional[str] = None, only_folds: Sequence[str] = ()) -> Path:
    """`plan`: (domain, model, protocol, repeats). Appends each fold to out/runs.jsonl.
    `only_folds`: fold keys (e.g. new-f1) to run, the others skipped; empty = all.
    `workers`: processes training an ensemble's members side by side (train.fit); the folds'
    results are the same as with one, only the recorded seconds change. `keep_networks`: a folder
    to save each fold's networks in (DOMAIN-MODEL-FOLD.pt); `networks_from`: such a folder, whose
    networks a fold decodes instead of training where they fit it (kept_networks). `ray`: run
    each fold as a Ray task of `workers` CPUs (experiments.grid); the lines are the same, in the
    order the folds finish."""
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    runs = out / "runs.jsonl"
    done = {(r["domain"], r["model"], r["fold"]) for r in read_runs(runs)}
    jobs = []
    planned_keys = set()
    for domain, name, protocol, repeats in plan:
        specs = load_corpus(domain, rounds=PROTOCOL_ROUNDS[protocol])
        for key, _, _ in plan_folds(specs, protocol, repeats):
            planned_keys.add(key)
            if (domain, name, key) in done or (only_folds and key not in only_folds):
                continue
            done.add((domain, name, key))  # a later plan step (e.g. cv3 after cv1) must not redo it
            jobs.append(Job(f"{domain} {name} {key}", fold_job,
                            {"domain": domain, "name": name, "protocol": protocol, "repeats": repeats, "key": key,
                             "workers": workers, "keep_networks": keep_networks, "networks_from": networks_from},
                            cpus=workers))

    unknown = sorted(set(only_folds) - planned_keys)
    if unknown:
        raise UnknownFold(f"no fold of the plan is called {', '.join(unknown)} (the plan's folds: {', '.join(sorted(planned_keys))})")

    def record(job: Job, result: dict) -> None:
        with runs.open("a") as fh:
            fh.write(json.dumps(result) + "\n")

    run_jobs(jobs, record, ray=ray, on_start=(lambda job: progress(job.name)) if progress else None)
    return runs


def trained_config(saved: dict) -> Optional[ModelConfig]:
    """The config that trained a saved model or fold's networks: recorded with them (a shipped
    file, a kept fold), or for older kept files their model's registration, None where it is gone."""
    return ModelConfig(**saved["cfg"]) if "cfg" in saved else MODELS.get(saved["name"])


def kept_networks(folder: Path, domain: str, name: str, key: str, train_idx: Sequence[int],
                  test_idx: Sequence[int]) -> Optional[dict]:
    """A fold's saved networks (run_fold's `keep`) that `name` can decode as its own, or None: the
    same fold, trained by a model whose training is `name`'s (networks_config: the two differ in
    decoding choices only) with at least as many members (member m trains with seed s + m
    whatever the ensemble's size, so the first members of a larger one are a smaller one's).
    Networks retrain bit for bit only on the kind of CPU that trained them, so the fold keeps
    the machine recorded with them."""
    want = networks_config(MODELS[name])
    for path in sorted(folder.glob(f"{domain}-*-{key}.pt")):
        saved = torch.load(path, weights_only=False)
        trained = trained_config(saved)
        if saved["domain"] == domain and trained is not None and networks_config(trained) == want \
                and saved["train"] == list(train_idx) and saved["test"] == list(test_idx) \
                and len(saved["nets"]) >= MODELS[name].ensemble:
            return saved
    return None


def read_runs(path: Path) -> list[dict]:
    return [json.loads(l) for l in path.read_text().splitlines() if l.strip()] if path.is_file() else []
