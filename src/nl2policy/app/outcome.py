"""What a run means to the person who started it: how far it has got (steps of the steps it
will really train, and a time estimate), and, once finished, a readable result (returns before
and after, the change, the time taken) with a sentence saying why the tree did or did not change.

The Optimize page shows these as they are; they are computed here so the API gives the same
words to any client.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Optional

from nl2policy.limits import trained_steps

SAME = 1e-6


def progress(run: dict) -> dict[str, Any]:
    """{"done", "total", "seconds", "eta_seconds"}: `done` never exceeds `total`, the steps the
    run really trains (its request rounded up to whole PPO rollouts)."""
    total = trained_steps(run["domain"], run["steps"])
    summary = run.get("summary") or {}
    done, seconds = 0, None
    if run["status"] == "finished" and summary:
        done, seconds = total, summary.get("seconds")
    else:
        try:
            state = json.loads((Path(run["out_dir"]) / "state.json").read_text())
            done, seconds = int(state.get("steps", 0)), float(state.get("seconds", 0.0))
        except (OSError, ValueError, TypeError):
            pass
    done = min(done, total)
    eta = None
    if run["status"] == "running" and done > 0 and seconds:
        eta = round(seconds / done * (total - done), 1)
    return {"done": done, "total": total, "seconds": None if seconds is None else round(seconds, 1), "eta_seconds": eta}


def result(summary: Optional[dict], changed: list[int]) -> Optional[dict[str, Any]]:
    """The finished run's numbers rounded for reading, and a verdict in words."""
    if not summary:
        return None
    exact = "exact_initial_tree" in summary  # taxi: returns computed exactly, not sampled
    before = summary["exact_initial_tree"] if exact else summary["initial_mean_return"]
    after = summary["exact_final_tree"] if exact else summary["final_mean_return"]
    how = "expected return (exact)" if exact else f"mean return over {summary.get('eval_episodes')} episodes"
    return {"before": round(before, 2), "after": round(after, 2), "change": round(after - before, 2), "measure": how,
            "seconds": summary.get("seconds"), "steps": summary.get("steps"), "changed_nodes": len(changed),
            "verdict": verdict(summary, changed, before, after)}


def verdict(summary: dict, changed: list[int], before: float, after: float) -> str:
    steps = summary.get("steps")
    learned = (" Training also moved a question's threshold to a value no question of the domain asks; that "
               "question is shown with its new value.") if summary.get("final_tree_has_raw_tests") else ""
    return _verdict(summary, changed, before, after, steps) + learned


def _verdict(summary: dict, changed: list[int], before: float, after: float, steps: Optional[int]) -> str:
    if changed:
        if after > before + SAME:
            return f"Training found a better tree: {len(changed)} node(s) changed (in yellow)."
        return (f"Training changed {len(changed)} node(s), but the new tree does no better than yours "
                f"({after:.2f} against {before:.2f}): keep yours, or try more steps or another seed.")
    best = summary.get("exact_best_tree")
    if best is not None and best > before + SAME:
        return (f"The final tree is the same as yours, but at step {summary.get('best_tree_step')} training passed a "
                f"better one ({best:.2f}), saved as best_tree.json in the run folder.")
    return (f"Your tree did not change: in {steps:,} steps training found no better tree than yours. Either none "
            "exists with these questions, or the run was too short to find it: try more steps or another seed.")
