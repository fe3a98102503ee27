"""Where the project keeps user state (trained translators, the app database, run folders).

``NL2POLICY_HOME`` overrides the platform's user data directory, so tests and CI can use a
throwaway folder.
"""

from __future__ import annotations

import os
from pathlib import Path

from platformdirs import user_data_dir


def home() -> Path:
    path = Path(os.environ.get("NL2POLICY_HOME") or user_data_dir("nl2policy"))
    path.mkdir(parents=True, exist_ok=True)
    return path
