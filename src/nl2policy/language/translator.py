"""The trained translator: an ensemble of networks with its word vocabulary, which reads
descriptions into network inputs and decodes them into valid trees (decoding.py).

Kept apart from the training loop (train.py): loading a saved model and translating need only this.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Sequence

import torch

from nl2policy.domains import get_domain
from nl2policy.language.decoding import Allow, Hypothesis, beam_search, search
from nl2policy.language.findings import Findings, FindingsModel
from nl2policy.language.models.config import ModelConfig
from nl2policy.language.models.network import Batch, Translator, build_network
from nl2policy.language.models.pretrained import DIM as MINILM_DIM, MiniLMCache
from nl2policy.language.text import WordVocab, split_sentences
from nl2policy.trees import Tree

MAX_SENT_WORDS = 60


@dataclass
class Encoded:
    """One description ready for the network."""

    ids: list[int]
    sent_lengths: list[int]
    mini: Optional[torch.Tensor]


@dataclass
class TrainedTranslator:
    domain: str
    name: str
    cfg: ModelConfig
    words: WordVocab
    nets: list[Translator]  # an ensemble: decoding averages their step probabilities
    cache: MiniLMCache = field(default_factory=MiniLMCache, repr=False)
    history: list[float] = field(default_factory=list, repr=False)  # mean training loss per epoch
    beam: Optional[int] = None  # hypotheses kept while decoding (1 = greedy); None: the config's
    findings_cost: Optional[float] = None  # weight of the learned findings in decoding (see ModelConfig); None: the config's
    findings: Optional[FindingsModel] = field(default=None, repr=False)  # the learned findings (language/findings.py)
    ensemble: Optional[int] = None  # decode with the first n networks only; None: all of them
    length_norm: Optional[float] = None  # the beam's ranking, log-probability / nodes ** length_norm; None: the config's
    stack_members: bool = True  # flat encoders: decode all members as one batch (False: one by one, same result)

    def decoding(self, setting: str) -> float:
        """A decoding setting (`findings_cost`, `beam`, ...): this translator's override, else its config's."""
        own = getattr(self, setting)
        return getattr(self.cfg, setting) if own is None else own

    @property
    def net(self) -> Translator:
        """The first network (the only one unless the config asks for an ensemble)."""
        return self.nets[0]

    @classmethod
    def from_states(cls, domain: str, name: str, cfg: ModelConfig, words: Sequence[str], states: Sequence[dict],
                    cache: MiniLMCache) -> TrainedTranslator:
        """A translator from saved networks: its word vocabulary (`words.itos[2:]`, as saved) and
        each network's state dict, in eval mode (a saved model file, a fold's kept networks)."""
        model = cls(domain, name, cfg, WordVocab(words), [], cache)
        for state in states:
            net = model.new_net()
            net.load_state_dict(state)
            model.nets.append(net.eval())
        return model

    def new_net(self) -> Translator:
        return build_network(self.cfg, len(self.words), len(self.tree_tokens))

    @property
    def tree_tokens(self) -> list[str]:
        """The labels the decoder scores: the domain's questions, then its actions."""
        vocab = get_domain(self.domain).vocab
        return list(vocab.question_ids) + list(vocab.action_ids)

    def encode(self, text: str) -> Encoded:
        sentences = split_sentences(text) or [[]]
        sentences = [s[:MAX_SENT_WORDS] for s in sentences if s] or []
        flat = [t for s in sentences for t in s]
        mini = torch.from_numpy(self.cache.get(text, flat, self.cfg.minilm_layers)) if self.cfg.minilm and flat else None
        if self.cfg.minilm and mini is None:
            mini = torch.zeros(self.cfg.minilm_layers + 1, 0, MINILM_DIM, dtype=torch.float16)
        return Encoded(self.words.encode(t.text for t in flat), [len(s) for s in sentences], mini)

    @torch.inference_mode()
    def predict(self, texts: Sequence[str], batch_size: int = 64,
                found: Optional[Sequence[Findings]] = None) -> list[tuple[Tree, dict[int, float]]]:
        """Grammar-constrained decoding (beam search, greedy when `beam` is 1). Returns (tree, {grid slot: probability}).
        `found`: the texts' findings if the caller has read them (`read_findings`), else read here."""
        for net in self.nets:
            if net.training:  # eval() walks every submodule: a cost per call otherwise
                net.eval()
        out = []
        for i in range(0, len(texts), batch_size):
            chunk = list(texts[i:i + batch_size])
            part = None if found is None else list(found[i:i + batch_size])
            out += beam_search(self, collate([self.encode(t) for t in chunk]), chunk, part)
        return out

    @torch.inference_mode()
    def hypotheses(self, text: str, found: Optional[Findings] = None, allow: Optional[Allow] = None,
                   width: Optional[int] = None) -> list[Hypothesis]:
        """One text's finished hypotheses, best first (decoding.search): `allow` restricts the
        trees built, `width` sets the beam."""
        for net in self.nets:
            if net.training:
                net.eval()
        return search(self, collate([self.encode(text)]), [text], None if found is None else [found], [allow], width)[0]

    def read_findings(self, texts: Sequence[str]) -> Optional[list[Findings]]:
        """What the texts say about their trees (findings.py), or None for a model without
        findings: the one reading that both decoding and the warnings of `translate` use."""
        return self.findings.read(texts) if self.findings is not None else None


def collate(items: Sequence[Encoded]) -> Batch:
    B = len(items)
    N = max(1, max(len(e.ids) for e in items))
    S = max(1, max(len(e.sent_lengths) for e in items))
    W = max([1] + [l for e in items for l in e.sent_lengths])
    words = torch.zeros(B, N, dtype=torch.long)
    sent_index = torch.full((B, S, W), N, dtype=torch.long)
    sent_lengths = torch.zeros(B, S, dtype=torch.long)
    for b, e in enumerate(items):
        words[b, : len(e.ids)] = torch.tensor(e.ids, dtype=torch.long)
        pos = 0
        for s, n in enumerate(e.sent_lengths):
            sent_index[b, s, :n] = torch.arange(pos, pos + n)
            sent_lengths[b, s] = n
            pos += n
    minis = None
    if items[0].mini is not None:
        minis = torch.zeros(B, items[0].mini.shape[0], N, items[0].mini.shape[2])
        for b, e in enumerate(items):
            minis[b, :, : e.mini.shape[1]] = e.mini.float()
    return Batch(words, torch.tensor([max(1, len(e.ids)) for e in items]), minis, sent_index, sent_lengths,
                 torch.tensor([max(1, len(e.sent_lengths)) for e in items]))
