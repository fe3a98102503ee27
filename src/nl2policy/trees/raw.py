"""A learned test that no dictionary question names, and how a person reads it.

PPO moves a DDT node's threshold; where it ends far from every question's (further than the
domain's ``match_tolerance``), discretization keeps it as ``raw:<feature><op><value>``, e.g.
``raw:gap_ahead<0.2281`` ("yes" when the feature is below 0.2281). The id is exact and is what
tree JSON stores, so a tree handed back can be evaluated, edited and optimized again. People read
it in the domain's units (its ``[units]`` table): "Is the gap to the car ahead in my lane less
than 22.8 m?".
"""

from __future__ import annotations

import math
import re
from decimal import ROUND_HALF_UP, Decimal
from dataclasses import dataclass
from typing import Optional

RAW_PREFIX = "raw:"
_RAW = re.compile(r"raw:([A-Za-z_][A-Za-z0-9_]*)([<>])([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


@dataclass(frozen=True)
class FeatureUnit:
    """How a feature reads: `name` in words ("the gap to the car ahead in my lane"), and
    `scale` x feature value = the value in `unit` ("m")."""

    name: str
    scale: float = 1.0
    unit: str = ""


@dataclass(frozen=True)
class RawTest:
    """``feature > value`` (greater) or ``feature < value``: "yes" when it holds."""

    feature: str
    greater: bool
    value: float

    @property
    def id(self) -> str:
        return f"{RAW_PREFIX}{self.feature}{'>' if self.greater else '<'}{self.value:.4f}"

    def wording(self, unit: Optional[FeatureUnit] = None) -> str:
        unit = unit or FeatureUnit(self.feature)
        amount = three_digits(self.value * unit.scale) + (f" {unit.unit}" if unit.unit else "")
        return f"Is {unit.name} {'more' if self.greater else 'less'} than {amount}?"


def three_digits(value: float) -> str:
    """`value` to 3 significant digits, halves rounded up on the exact binary value and no
    exponent: what the pages' JavaScript writes (Number(v.toPrecision(3))) for such values."""
    exact = Decimal(value + 0.0)  # + 0.0: no "-0"
    if exact == 0:
        return "0"
    rounded = exact.quantize(Decimal(1).scaleb(exact.adjusted() - 2), rounding=ROUND_HALF_UP)
    text = format(rounded, "f")
    return text.rstrip("0").rstrip(".") if "." in text else text


def parse_raw(question: str) -> Optional[RawTest]:
    """The test a ``raw:`` id states, or None when `question` is not one or is malformed."""
    match = _RAW.fullmatch(question)
    if match is None:
        return None
    value = float(match.group(3))
    if not math.isfinite(value):
        return None
    return RawTest(match.group(1), match.group(2) == ">", value)
