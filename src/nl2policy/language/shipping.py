"""Training a shipped translator: the whole corpus, the version's recipe, saved where
translate.py finds it. Kept apart from translate.py so that loading a model and translating
never import the training stack (augmentation, the synthetic generator, the training loop)."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path
from typing import Callable, Optional

import torch

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.dataset import member_pairs
from nl2policy.language.members import default_workers, is_current
from nl2policy.language.models.config import DEFAULT_MODEL, MODELS
from nl2policy.language.text import tokenize
from nl2policy.language.train import fit
from nl2policy.language.translate import STOPWORDS, model_path


TRAINING_ROUNDS = (1, 2)
"""The corpus rounds a shipped model trains on: all of them (round 2's trees are new to round 1)."""


def train_default(domain: str, name: str = DEFAULT_MODEL, seed: int = 0,
                  progress: Optional[Callable[[int, int], None]] = None, out: Optional[Path] = None,
                  workers: Optional[int] = None) -> Path:
    """Train on the whole shared corpus and save into `out` (default: the user's model folder);
    resumes from `<model>.ckpt` if one exists. The file holds the config and word vocabulary
    too, so loading it needs nothing else. An ensemble's members train in `workers` processes
    (default: one per CPU core, at most one per member); the networks do not depend on it."""
    get_domain(domain)
    if name not in MODELS:
        raise KeyError(f"unknown model {name!r}; known: {', '.join(MODELS)}")
    cfg = MODELS[name]
    path = model_path(domain, name, out)
    ckpt = path.with_suffix(".ckpt")
    path.parent.mkdir(parents=True, exist_ok=True)
    state = torch.load(ckpt, weights_only=False) if ckpt.is_file() else None
    if state is not None and not is_current(state):
        print(f"ignoring {ckpt}: a checkpoint of an older version; training afresh", file=sys.stderr)
        state = None
    specs = load_corpus(domain, rounds=TRAINING_ROUNDS)
    pairs = member_pairs(domain, specs, range(len(specs)), cfg, seed)
    vocab_texts = [s.description for s in specs]  # the word vocabulary: real descriptions only

    def save_checkpoint(checkpoint: dict) -> None:
        tmp = ckpt.with_suffix(".tmp")
        torch.save(checkpoint, tmp)
        tmp.replace(ckpt)

    model = fit(domain, name, cfg, pairs, seed, progress=progress, vocab_texts=vocab_texts, state=state, on_epoch=save_checkpoint,
                workers=workers or default_workers(cfg))
    tmp = path.with_suffix(".tmp")
    torch.save({"domain": domain, "name": name, "cfg": cfg.to_dict(), "words": model.words.itos[2:],
                "nets": [net.state_dict() for net in model.nets], "lexicon": topic_lexicon(domain),
                "findings": model.findings.state() if model.findings is not None else None}, tmp)
    tmp.replace(path)
    ckpt.unlink(missing_ok=True)
    return path


def topic_lexicon(domain: str) -> dict[str, list[str]]:
    """Words typical of each domain's descriptions (in >= 5 of its specs, >= 4x as often as
    in the other domain's): the on-topic detector's evidence."""
    df = {d: Counter(w for s in load_corpus(d, rounds=TRAINING_ROUNDS) for w in set(tokenize(s.description)))
          for d in DOMAINS}
    out = {}
    for d in DOMAINS:
        others = Counter()
        for o in DOMAINS:
            if o != d:
                others.update(df[o])
        out[d] = sorted(w for w, c in df[d].items() if c >= 5 and (c + 1) / (others[w] + 1) >= 4 and w not in STOPWORDS)
    return out
