"""Where the project keeps user state (trained translators, the app database, run folders).

``NL2POLICY_HOME`` overrides the platform's user data directory, so tests and CI can use a
throwaway folder.
"""

from __future__ import annotations

import os
from pathlib import Path


class HomeError(OSError):
    """The data folder cannot be made: the message names it and says what to do."""


def home() -> Path:
    if os.environ.get("NL2POLICY_HOME"):
        path = Path(os.environ["NL2POLICY_HOME"])
    else:
        from platformdirs import user_data_dir

        path = Path(user_data_dir("nl2policy"))
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise HomeError(f"cannot create the data folder {path}: {exc.strerror or exc}; "
                        "set NL2POLICY_HOME to a folder you can write") from exc
    return path
