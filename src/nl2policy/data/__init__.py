"""Where the shipped data lives.

The corpus is a copy of ``../shared/corpus`` taken by ``make corpus``, so a fresh clone works
anywhere. ``NL2POLICY_CORPUS`` points the project at another folder of the same shape.
"""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DATA = Path(__file__).resolve().parent


def corpus_dir() -> Path:
    """The corpus folder in use: ``$NL2POLICY_CORPUS`` if set, else the shipped copy."""
    override = os.environ.get("NL2POLICY_CORPUS")
    path = Path(override) if override else PACKAGE_DATA / "corpus"
    if not (path / "vocabulary.json").is_file():
        raise FileNotFoundError(f"no vocabulary.json in corpus folder {path} (check NL2POLICY_CORPUS)")
    return path
