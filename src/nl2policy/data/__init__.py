"""Where the shipped data lives.

The corpus is a copy of ``../shared/corpus`` taken by ``make corpus``, so a fresh clone works
anywhere. ``NL2POLICY_CORPUS`` points the project at another folder of the same shape.
"""

from __future__ import annotations

import os
from pathlib import Path

from nl2policy.errors import UserError

PACKAGE_DATA = Path(__file__).resolve().parent


class CorpusMissing(UserError, FileNotFoundError):
    """The corpus folder in use has no corpus in it."""


def corpus_dir() -> Path:
    """The corpus folder in use: ``$NL2POLICY_CORPUS`` if set, else the shipped copy."""
    override = os.environ.get("NL2POLICY_CORPUS")
    path = Path(override) if override else PACKAGE_DATA / "corpus"
    if not (path / "vocabulary.json").is_file():
        where = "NL2POLICY_CORPUS points to" if override else "the shipped corpus is missing from"
        raise CorpusMissing(f"no corpus in {path} ({where} it: no vocabulary.json there); "
                            + ("set NL2POLICY_CORPUS to a corpus folder or unset it" if override else "reinstall nl2policy"))
    return path
