"""Provenance for a written table: the command that made it, when, and with which Python and
torch, so every number under results/ can be made again."""

from __future__ import annotations

import platform
from datetime import datetime, timezone


def provenance(command: str) -> dict:
    import torch

    return {
        "command": command,
        "made": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "python": platform.python_version(),
        "torch": torch.__version__,
    }
