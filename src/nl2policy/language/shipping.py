"""Training a shipped translator: the whole corpus, the version's recipe, saved where
translate.py finds it. Kept apart from translate.py so that loading a model and translating
never import the training stack (augmentation, the synthetic generator, the training loop)."""

from __future__ import annotations

import dataclasses
import sys
from collections import Counter
from pathlib import Path
from typing import Callable, Optional

import torch

from nl2policy.domains import DOMAINS, get_domain
from nl2policy.language.corpus import load_corpus
from nl2policy.language.dataset import member_pairs
from nl2policy.language.members import default_workers, is_current
from nl2policy.language.models.config import DEFAULT_MODEL, MODELS, ModelConfig
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
    cfg = shipped_config(domain, name)
    path = model_path(domain, name, out)
    ckpt = path.with_suffix(".ckpt")
    path.parent.mkdir(parents=True, exist_ok=True)
    state = torch.load(ckpt, weights_only=False) if ckpt.is_file() else None
    if state is not None and not is_current(state):
        print(f"ignoring {ckpt}: a checkpoint of an older version; training afresh", file=sys.stderr)
        state = None
    specs = load_corpus(domain, rounds=TRAINING_ROUNDS)
    pairs = member_pairs(domain, specs, range(len(specs)), cfg, seed)
    # the word vocabulary: real descriptions only; a domain nobody has described yet (lunar) has
    # none, and takes its words from the first member's synthetic pairs
    vocab_texts = [s.description for s in specs] or None

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


def shipped_config(domain: str, name: str = DEFAULT_MODEL) -> ModelConfig:
    """The recipe `name` with the settings the domain's spec.toml changes ([translator]: lunar,
    which nobody has described, trains on more synthetic pairs)."""
    overrides = dict(get_domain(domain).translator)
    unknown = set(overrides) - set(MODELS[name].to_dict())
    if unknown:
        raise ValueError(f"{domain}/spec.toml: [translator] has unknown settings {sorted(unknown)}")
    return dataclasses.replace(MODELS[name], **overrides)


def topic_lexicon(domain: str) -> dict[str, list[str]]:
    """Words typical of each domain's descriptions (in >= 5 of its specs, >= 4x as often as in
    the other domains'): the on-topic detector's evidence. A domain nobody has described yet is
    read from its own wording instead (its dictionary and phrases.toml, each string a document,
    a word in >= 2 of them), so its lexicon is the domain's words, not a writer's."""
    df, least = {}, {}
    for d in DOMAINS:
        texts = [s.description for s in load_corpus(d, rounds=TRAINING_ROUNDS)]
        least[d] = 5 if texts else 2
        df[d] = Counter(w for text in (texts or _own_wording(d)) for w in set(tokenize(text)))
    out = {}
    for d in DOMAINS:
        others = Counter()
        for o in DOMAINS:
            if o != d:
                others.update(df[o])
        out[d] = sorted(w for w, c in df[d].items() if c >= least[d] and (c + 1) / (others[w] + 1) >= 4 and w not in STOPWORDS)
    return out


def _own_wording(domain: str) -> list[str]:
    """Every string in which the domain words itself: its dictionary and its phrases."""
    d = get_domain(domain)
    texts = list(d.vocab.questions.values()) + list(d.vocab.actions.values())

    def strings(node) -> None:
        if isinstance(node, str):
            texts.append(node)
        elif isinstance(node, dict):
            for v in node.values():
                strings(v)
        elif isinstance(node, list):
            for v in node:
                strings(v)

    strings(d.phrases)
    return texts
