"""Writing result tables: Markdown for people, JSON for programs, each with the command that
made it, so every number under results/ can be made again."""

from __future__ import annotations

import json
import platform
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path


def provenance(command: str) -> dict:
    import torch

    return {
        "command": command,
        "made": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "python": platform.python_version(),
        "torch": torch.__version__,
    }


def write_returns_table(domain: str, rows: list, out: Path, command: str) -> Path:
    """results/<out>/tree_returns_<domain>.md and .json."""
    out.mkdir(parents=True, exist_ok=True)
    meta = provenance(command)
    lines = [f"# Mean episode return of reference policies: {domain}", "", f"Made by: `{command}`  ", f"On: {meta['made']}", ""]
    lines += ["| policy | mean return | stderr | episodes |", "|---|---:|---:|---:|"]
    for r in rows:
        eps = r.episodes if r.episodes else "exact"
        se = f"{r.stderr:.3f}" if r.episodes else "-"
        lines.append(f"| {r.policy} | {r.mean_return:.3f} | {se} | {eps} |")
    for r in rows:
        if r.tree:
            lines.append(f"\n{r.policy}: `{json.dumps(r.tree)}`")
    lines.append("")
    md = out / f"tree_returns_{domain}.md"
    md.write_text("\n".join(lines))
    (out / f"tree_returns_{domain}.json").write_text(json.dumps({"meta": meta, "rows": [asdict(r) for r in rows]}, indent=2))
    return md
