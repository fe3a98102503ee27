"""Tokens and sentences from free-form descriptions, whatever the writer's style.

Writers text in lowercase with abbreviations ("ur", "b/c", "ppl"), write numbered steps
and bullets, pseudo-code with camelCase names ("hasPassenger"), and arrows ("->", "→").
The translators see one normalised stream of lowercase word tokens, grouped in sentences
(HAN2Tree attends per sentence). Each token keeps the character span it came from, so the
contextual MiniLM vectors, which are computed on the raw text, can be aligned to it.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from typing import Iterable, Sequence

PAD, UNK = "<pad>", "<unk>"
MIN_FREQ = 5
"""Words seen fewer times than this in a training fold become <unk> (the paper's rule)."""

# Texting shorthand -> plain words (general English texting and contractions, not read off the
# corpus). Several expand to more than one token.
SHORTHAND = {
    "u": "you", "ur": "your", "r": "are", "ppl": "people", "b/c": "because", "bc": "because",
    "cuz": "because", "coz": "because", "w/": "with", "w/o": "without", "rn": "right now",
    "n": "and", "&": "and", "thru": "through", "tho": "though", "pls": "please", "plz": "please",
    "im": "i am", "dont": "do not", "don't": "do not", "doesnt": "does not", "doesn't": "does not",
    "isnt": "is not", "isn't": "is not", "theres": "there is", "there's": "there is",
    "thats": "that is", "that's": "that is", "its": "it is", "it's": "it is", "can't": "can not",
    "cant": "can not", "won't": "will not", "wont": "will not", "aren't": "are not",
    "i'm": "i am", "you're": "you are", "youre": "you are", "i've": "i have", "you've": "you have",
    "didn't": "did not", "hasn't": "has not", "haven't": "have not", "nobody's": "nobody is",
    "someone's": "someone is", "somebody's": "somebody is", "what's": "what is", "here's": "here is",
    "let's": "let us", "shouldn't": "should not", "wasn't": "was not", "else:": "else",
    "2": "to", "b4": "before", "gonna": "going to", "wanna": "want to", "ok": "okay", "k": "okay",
    "y": "yes", "yep": "yes", "yeah": "yes", "yup": "yes", "nope": "no", "nah": "no",
}
ARROWS = ("->", "→", "=>", "-->", "⇒")

_WORD = re.compile(r"->|-->|=>|→|⇒|[A-Za-z]+(?:'[A-Za-z]+)?(?:/[a-z]*)?|\d+|[^\sA-Za-z\d]")
_CAMEL = re.compile(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+")
_BULLET = re.compile(r"^\s*(?:[-*•]|\d+[.)]|[a-zA-Z][.)])\s+")
_SENTENCE_END = re.compile(r"(?<=[.!?;])\s+(?!->|→|=>)|\n+")


@dataclass(frozen=True)
class Token:
    """A normalised word and the span of the raw text it was read from."""

    text: str
    start: int
    end: int


def _words(raw: str, offset: int) -> list[Token]:
    out: list[Token] = []
    for m in _WORD.finditer(raw):
        piece, start = m.group(0), offset + m.start()
        if piece in ARROWS:
            out.append(Token("->", start, start + len(piece)))
            continue
        lower = piece.lower()
        if lower in SHORTHAND:
            out += [Token(w, start, start + len(piece)) for w in SHORTHAND[lower].split()]
            continue
        if any(c.isupper() for c in piece[1:]) and piece.isalpha():  # camelCase / PascalCase name
            for sub in _CAMEL.finditer(piece):
                out.append(Token(sub.group(0).lower(), start + sub.start(), start + sub.end()))
            continue
        if lower.endswith("'s") and len(lower) > 2:
            out += [Token(lower[:-2], start, start + len(piece) - 2), Token("'s", start + len(piece) - 2, start + len(piece))]
            continue
        if lower in {",", ".", "!", "?", ";", ":", "(", ")", '"', "'", "`"} or piece == "_":
            continue  # punctuation carries no policy; sentences are split before this
        out.append(Token(lower, start, start + len(piece)))
    return out


def split_sentences(text: str) -> list[list[Token]]:
    """Sentences (lists of tokens). Lines, bullets and numbered steps each start a sentence;
    inside a line, sentence punctuation splits. Empty sentences are dropped."""
    return [list(s) for s in _split_cached(text)]


@lru_cache(maxsize=256)
def _split_cached(text: str) -> tuple[tuple[Token, ...], ...]:
    """One translation reads a text three times (emptiness, topic, encoder): split it once."""
    return tuple(tuple(s) for s in _split(text))


def _split(text: str) -> list[list[Token]]:
    sentences: list[list[Token]] = []
    pos = 0
    for line in text.split("\n"):
        line_start = pos
        pos += len(line) + 1
        bullet = _BULLET.match(line)
        body_start = bullet.end() if bullet else 0
        body = line[body_start:]
        # snake_case names: underscores read as spaces (same length, spans stay right)
        body = body.replace("_", " ")
        cut = 0
        for piece in _SENTENCE_END.split(body) + [None]:
            if piece is None:
                break
            idx = body.find(piece, cut)
            cut = idx + len(piece)
            toks = _words(piece, line_start + body_start + idx)
            if toks:
                sentences.append(toks)
    return sentences


def tokenize(text: str) -> list[str]:
    """All tokens of `text`, sentence boundaries dropped."""
    return [t.text for s in split_sentences(text) for t in s]


class WordVocab:
    """Word -> id, built from a training fold only; rare words map to <unk>."""

    def __init__(self, words: Sequence[str]) -> None:
        self.itos = [PAD, UNK, *words]
        self.stoi = {w: i for i, w in enumerate(self.itos)}

    @classmethod
    def build(cls, texts: Iterable[str], min_freq: int = MIN_FREQ) -> "WordVocab":
        counts = Counter(w for t in texts for w in tokenize(t))
        return cls(sorted(w for w, c in counts.items() if c >= min_freq))

    def __len__(self) -> int:
        return len(self.itos)

    def id(self, word: str) -> int:
        return self.stoi.get(word, 1)

    def encode(self, words: Iterable[str]) -> list[int]:
        return [self.id(w) for w in words]
