"""Training-fold augmentation: English rewordings that keep the meaning (contractions, the
connectives of english.toml swapped for their equivalents), standing in for the paper's
back-translation (which needs online translation models), and style noise (texting, typos,
a reflow into bullet lines).

Nothing here was written from the corpus descriptions: the rewordings are English grammar
(synthetic/english.toml), not a thesaurus of the writers' words.

Augmentation runs *after* the split, on training indices only: an augmented copy of a test
description in training would leak the test item. Each copy is a pure function of the spec
id, the copy number and the seed, so every fold that trains on a spec sees the same copy
(which lets the MiniLM cache be shared across folds) and runs are reproducible.
"""

from __future__ import annotations

import random
import re
import zlib
from typing import Sequence

from nl2policy.language.corpus import Spec
from nl2policy.language.synthetic.styles import texting, typos
from nl2policy.language.synthetic.words import english
from nl2policy.trees import Tree

CONTRACTIONS = [("do not", "don't"), ("does not", "doesn't"), ("is not", "isn't"), ("are not", "aren't"),
                ("there is", "there's"), ("it is", "it's"), ("cannot", "can't"), ("I am", "I'm"), ("you are", "you're")]
"""English contractions, each way round."""

EQUIVALENT_GROUPS = ("else", "if", "yes_reply", "no_reply", "otherwise_rule")
"""english.toml entries whose members may stand in for one another (single words only, so a
swap never splits a phrase)."""


def _rng(key: str, copy: int, seed: int) -> random.Random:
    return random.Random(zlib.crc32(f"{key}|{copy}|{seed}".encode()))


def _swaps() -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for group in EQUIVALENT_GROUPS:
        words = [w for w in english()[group] if re.fullmatch(r"[a-z]+", w)]
        for w in words:
            out.setdefault(w, []).extend(x for x in words if x != w)
    return out


def paraphrase(text: str, rng: random.Random, p: float = 0.4) -> str:
    """Contractions opened or closed, and connectives swapped for an equivalent, each with
    probability `p`."""
    for long, short in CONTRACTIONS:
        a, b = (long, short) if rng.random() < 0.5 else (short, long)
        text = re.sub(rf"\b{re.escape(a)}\b", lambda m: b if rng.random() < p else m.group(0), text)
    swaps = _swaps()
    pattern = re.compile(r"\b(" + "|".join(sorted(swaps, key=len, reverse=True)) + r")\b")
    return pattern.sub(lambda m: rng.choice(swaps[m.group(0)]) if rng.random() < p / 2 else m.group(0), text)


def style_noise(text: str, rng: random.Random) -> str:
    """Writers' surface habits: lowercase texting with shorthand, a reflow into bullet lines,
    typos."""
    roll = rng.random()
    if roll < 0.25:
        text = texting(text, rng)
    elif roll < 0.4 and "\n" not in text:
        parts = [s.strip() for s in re.split(r"(?<=[.!?])\s+", text) if s.strip()]
        bullet = rng.choice(["- ", "* ", "{n}. ", "• "])
        text = "\n".join(bullet.replace("{n}", str(i + 1)) + s.rstrip(".") for i, s in enumerate(parts))
    if rng.random() < 0.3:
        text = typos(text, rng)
    return text


def augment_text(text: str, key: str, copy: int, seed: int = 0) -> str:
    rng = _rng(key, copy, seed)
    return style_noise(paraphrase(text, rng), rng)


def augment_fold(specs: Sequence[Spec], train_idx: Sequence[int], copies: int, seed: int = 0) -> list[tuple[str, Tree]]:
    """Augmented (description, tree) pairs for the given TRAINING indices only."""
    return [(augment_text(specs[i].description, specs[i].id, c, seed), specs[i].tree)
            for i in train_idx for c in range(copies)]
