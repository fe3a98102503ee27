"""Training-fold augmentation: synonym replacement, a rule-based paraphrase standing in for
the paper's back-translation (which needs online translation models), and style noise.

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
from nl2policy.trees import Tree

# A small hand-made thesaurus for the words these descriptions use (our own list; WordNet is
# not installed and would need a system package). Only meaning-preserving swaps.
SYNONYMS: dict[str, list[str]] = {
    "drive": ["go", "head", "travel"], "go": ["head", "drive", "move"], "head": ["go", "drive"],
    "check": ["see", "look at", "ask"], "whether": ["if"], "should": ["must", "ought to", "will"],
    "passenger": ["rider", "customer", "fare"], "passengers": ["riders", "customers", "people"],
    "someone": ["somebody", "a person"], "nobody": ["no one"], "empty": ["vacant"],
    "wait": ["hang around", "stay"], "waiting": ["hanging around", "staying"],
    "long": ["lengthy"], "heavy": ["bad", "jammed"], "traffic": ["congestion"],
    "city": ["town centre", "city"], "straight": ["directly", "right away"],
    "close": ["near", "nearby"], "free": ["clear", "open", "empty"], "clear": ["free", "open"],
    "speed up": ["accelerate", "go faster"], "slow down": ["brake", "decelerate"],
    "fast": ["quickly", "at speed"], "car": ["vehicle"], "cars": ["vehicles"],
    "lane": ["lane"], "change": ["switch", "move"], "move": ["switch", "change"],
    "rightmost": ["far right", "right-most"], "leftmost": ["far left", "left-most"],
    "otherwise": ["if not", "else"], "then": ["next"],
    "first": ["to start", "first of all"], "always": ["every time"], "because": ["since", "as"],
    "since": ["because", "as"], "simple": ["easy", "basic"], "keep": ["stay in", "hold"],
    "behind": ["at the back of", "in back of"], "ahead": ["in front"], "in front": ["ahead"],
    "big": ["large"], "quick": ["fast"], "really": ["truly", "very"], "think": ["believe", "feel"],
}
_SYN_RE = re.compile(r"\b(" + "|".join(sorted(map(re.escape, SYNONYMS), key=len, reverse=True)) + r")\b", re.I)

# Paraphrase rules: (pattern, alternatives). Applied with probability, each keeps the policy.
PARAPHRASES: list[tuple[str, list[str]]] = [
    (r"\bIf it is not(?=[,.])", ["If not", "Otherwise", "If that is not the case"]),
    (r"\bIf it is(?=[,.])", ["If so", "If yes"]),
    (r"\bIf there is\b", ["When there is", "If there's"]),
    (r"\bIf there isn't\b", ["If there is no", "When there's no"]),
    (r"\bit should\b", ["it has to", "it needs to", "it will"]),
    (r"\bdo not\b", ["don't"]), (r"\bdon't\b", ["do not"]), (r"\bisn't\b", ["is not"]),
    (r"\bis not\b", ["isn't"]), (r"\bthere is\b", ["there's"]), (r"\bthere's\b", ["there is"]),
    (r"\bthe taxi\b", ["the cab", "my taxi", "it"]), (r"\bthe car\b", ["my car", "the vehicle"]),
    (r"\bcheck whether\b", ["find out if", "look at whether", "ask whether"]),
    (r"\belse\b", ["otherwise"]), (r"\botherwise\b", ["else", "if not"]),
]
TEXTING = {"you": "u", "your": "ur", "because": "b/c", "people": "ppl", "and": "n", "with": "w/",
           "are": "r", "to": "2", "there is": "theres", "that is": "thats", "okay": "ok"}
FILLER_MARKERS = ("proud", "rain", "sun", "love", "honestly", "coffee", "weather", "remember", "hamster")


def _rng(key: str, copy: int, seed: int) -> random.Random:
    return random.Random(zlib.crc32(f"{key}|{copy}|{seed}".encode()))


def replace_synonyms(text: str, rng: random.Random, p: float = 0.3) -> str:
    def swap(m: re.Match) -> str:
        word = m.group(0)
        if rng.random() > p:
            return word
        new = rng.choice(SYNONYMS[word.lower()])
        return new.capitalize() if word[:1].isupper() else new
    return _SYN_RE.sub(swap, text)


def paraphrase(text: str, rng: random.Random, p: float = 0.5) -> str:
    """Rule-based rewording; then, sometimes, drop a filler sentence (one that only chats)."""
    for pattern, options in PARAPHRASES:
        text = re.sub(pattern, lambda m: rng.choice(options) if rng.random() < p else m.group(0), text,
                      flags=re.I if pattern.islower() else 0)
    sentences = re.split(r"(?<=[.!])\s+", text)
    keep = [s for s in sentences if not (any(w in s.lower() for w in FILLER_MARKERS) and rng.random() < 0.7)]
    return " ".join(keep) if keep and "\n" not in text else text


def style_noise(text: str, rng: random.Random) -> str:
    """Writers' surface habits: lowercase texting with shorthand, dropped punctuation, typos,
    or a reflow into bullet lines."""
    roll = rng.random()
    if roll < 0.3:
        text = text.lower()
        for long, short in TEXTING.items():
            if rng.random() < 0.6:
                text = re.sub(rf"\b{long}\b", short, text)
        text = text.replace("'", "")
    elif roll < 0.45 and "\n" not in text:
        parts = [s.strip() for s in re.split(r"(?<=[.!?])\s+", text) if s.strip()]
        bullet = rng.choice(["- ", "* ", "{n}. ", "• "])
        text = "\n".join(bullet.replace("{n}", str(i + 1)) + s.rstrip(".") for i, s in enumerate(parts))
    if rng.random() < 0.3:  # a couple of typos: swap two letters inside a word
        words = text.split(" ")
        for _ in range(2):
            i = rng.randrange(len(words))
            w = words[i]
            if len(w) > 4 and w.isalpha():
                j = rng.randrange(1, len(w) - 2)
                words[i] = w[:j] + w[j + 1] + w[j] + w[j + 2:]
        text = " ".join(words)
    return text


def augment_text(text: str, key: str, copy: int, seed: int = 0) -> str:
    rng = _rng(key, copy, seed)
    return style_noise(paraphrase(replace_synonyms(text, rng), rng), rng)


def augment_fold(specs: Sequence[Spec], train_idx: Sequence[int], copies: int, seed: int = 0) -> list[tuple[str, Tree]]:
    """Augmented (description, tree) pairs for the given TRAINING indices only."""
    return [(augment_text(specs[i].description, specs[i].id, c, seed), specs[i].tree)
            for i in train_idx for c in range(copies)]
