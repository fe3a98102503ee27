"""Named model configurations: which encoder, decoder, inputs and training data."""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Optional, Union


@dataclass(frozen=True)
class ModelConfig:
    encoder: str  # "flat" (BiGRU over all words); the lab adds "han" (words per sentence, then sentences)
    decoder: str  # "tree" (state from the parent node); the lab adds "seq" (state follows the previous token)
    minilm: bool  # fuse frozen MiniLM layers into the word inputs
    synthetic: Union[int, tuple[int, ...]]  # synthetic random-tree pairs added to training (0 = none); a list: member m gets entry m % len
    aug_copies: int = 1  # augmented copies of each training description
    epochs: int = 30  # with the cosine schedule in train.fit; 10 left the decoder undertrained
    hidden: int = 64
    embed: int = 48
    lr: float = 3e-3
    batch: int = 32
    dropout: float = 0.3
    ensemble: int = 1  # networks trained with consecutive seeds; decoding averages them
    member_draws: bool = False  # each ensemble member trains on its own augmented and synthetic draw
    beam: int = 1  # decoding: hypotheses kept by the beam search (1 = greedy)
    minilm_layers: int = 3  # MiniLM transformer layers run (of 6): accuracy against latency
    seed_offset: int = 0  # added to every member's seed and draw: another training run of the same recipe
    findings_cost: float = 0.0  # decoding: weight of the learned findings' log-agreement (language/findings.py)
    length_norm: float = 0.0  # decoding: the beam ranks trees by log-probability / nodes ** length_norm (0 = the sum)
    findings: bool = False  # train the learned findings even where decoding gives them no weight: translate's warnings read them

    def __post_init__(self) -> None:
        if isinstance(self.synthetic, list):  # a recipe file's list: a tuple keeps the config hashable
            object.__setattr__(self, "synthetic", tuple(self.synthetic))
        counts = self._synthetic_counts()
        if not counts or any(not isinstance(n, int) or n < 0 for n in counts):
            raise ValueError(f"synthetic must be a count of pairs or a list of counts (whole numbers >= 0), not {self.synthetic!r}")
        if len(set(counts)) > 1 and not self.member_draws:
            raise ValueError("synthetic counts that differ between members need member_draws = true (each member its own draw)")

    def _synthetic_counts(self) -> tuple:
        return self.synthetic if isinstance(self.synthetic, tuple) else (self.synthetic,)

    def synthetic_for(self, member: int) -> int:
        """Synthetic pairs in ensemble member `member`'s draw. A list of counts mixes members that
        lean on the corpus's own trees (few synthetic pairs) with members that lean on the tree
        grammar (many), in turn: member m gets entry m % len."""
        counts = self._synthetic_counts()
        return counts[member % len(counts)]

    def to_dict(self) -> dict:
        return asdict(self)


DECODING_FIELDS = ("ensemble", "beam", "findings_cost", "length_norm", "findings")
"""The settings that leave the trained networks as they are: how they are decoded (`ensemble`: how
many of them), and whether the learned findings train beside them."""


def networks_config(cfg: ModelConfig) -> ModelConfig:
    """`cfg` without its decoding choices: two models train the same networks (on the same fold and
    kind of CPU) exactly when these are equal."""
    return replace(cfg, **{f: getattr(ModelConfig, f) for f in DECODING_FIELDS})


MODELS: dict[str, ModelConfig] = {
    # tiny and quick, for smoke tests of the plumbing (CLI, saving, loading); not a translator to use
    "smoke": ModelConfig("flat", "tree", False, 0, aug_copies=0, epochs=1, hidden=16, embed=16, batch=64),
}
"""The product's configs: the shipped version (DEFAULT_MODEL, from its recipe) and the smoke
model. The lab registers the paper's four and the default's parts (experiments/translation/baselines.py)."""
RECIPES = Path(__file__).resolve().parent.parent / "recipes"
"""The shipped translator's recipe, one small file (recipes/v7.toml). Earlier versions' and
candidates' recipes live in the lab (experiments/translation/recipes/)."""


def load_recipe(version: str, folder: Optional[Path] = None) -> ModelConfig:
    """A version's config from its recipe file (in `folder`, default RECIPES); fields it leaves
    out take their defaults."""
    path = (folder or RECIPES) / f"{version}.toml"
    data = tomllib.loads(path.read_text())
    unknown = sorted(set(data) - {f.name for f in fields(ModelConfig)})
    if unknown:
        raise ValueError(f"{path}: unknown settings {', '.join(unknown)}")
    return ModelConfig(**data)


DEFAULT_MODEL = "v7"
"""The shipped translator's version: its models are named DOMAIN-VERSION (taxi-v7)."""
MODELS[DEFAULT_MODEL] = load_recipe(DEFAULT_MODEL)
