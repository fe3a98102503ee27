"""Training an ensemble's members resumably, one by one or side by side in worker processes.

A member depends only on its seed and its draw of training pairs, so members can train in
forked processes of one torch thread each and come out as the same networks; `train.fit`
runs the loop of one member and uses these pieces for what lies around it: the checkpoint of
every member's progress, and the workers.
"""

from __future__ import annotations

import io
import multiprocessing
import os
from queue import Empty
from typing import Any, Callable, Optional

import torch

from nl2policy.language.models.config import ModelConfig

SIDE_JOB = -1
"""The job id of `train_forked`'s side job (members are 0, 1, ...)."""


def default_workers(cfg: ModelConfig) -> int:
    """One worker per CPU core this process may use, and no more than there are members."""
    return min(len(os.sched_getaffinity(0)), cfg.ensemble)


def is_current(state: dict) -> bool:
    """Whether a checkpoint dict has this version's layout (older ones held one member at a time)."""
    return "partial" in state


class MemberCheckpoints:
    """What a resumable ensemble training has done: {"finished": {member: network state},
    "history": {member: mean loss per epoch}, "partial": {member: that member's network,
    optimizer and random states after its last epoch}}. Every save passes the whole dict on."""

    def __init__(self, state: Optional[dict], on_epoch: Optional[Callable[[dict], None]]) -> None:
        if state is not None and not is_current(state):
            raise ValueError("this checkpoint comes from an older version of nl2policy; delete it to train afresh")
        state = state or {}
        self.finished: dict[int, dict] = dict(state.get("finished", {}))
        self.history: dict[int, list[float]] = dict(state.get("history", {}))
        self.partial: dict[int, dict] = dict(state.get("partial", {}))
        self.on_epoch = on_epoch

    def _emit(self) -> None:
        if self.on_epoch:
            self.on_epoch({"finished": dict(self.finished), "history": dict(self.history), "partial": dict(self.partial)})

    def save(self, member: int, checkpoint: dict) -> None:
        self.partial[member] = checkpoint
        self._emit()

    def finish(self, member: int, net_state: dict, history: list[float]) -> None:
        self.finished[member], self.history[member] = net_state, history
        self.partial.pop(member, None)
        self._emit()


def _dumps(obj) -> bytes:
    """Tensors cross the process boundary as bytes: torch's own pickling of tensors through a
    multiprocessing queue shares memory with the sender, which may have exited by then."""
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def _loads(data: bytes):
    return torch.load(io.BytesIO(data), weights_only=False)


def _job_name(job: int) -> str:
    return "the learned findings" if job == SIDE_JOB else f"ensemble member {job}"


def train_forked(members: list[int], train_member: Callable, workers: int,
                  report: Callable[[int, int, int], None], ckpt: MemberCheckpoints,
                  side_job: Optional[Callable[[], Any]] = None) -> Any:
    """Train `members` in up to `workers` forked processes (one CPU thread each); their
    progress, checkpoints and results come back through one queue and are handled here, in the
    parent, in the order they arrive. A worker that fails stops the others and raises.

    `side_job` (the learned findings, which train on member 0's pairs) runs as one more job of
    the same pool, first, and its result is returned: run after the members in the parent, it
    left one core idle for minutes at the end of every training."""
    torch.optim.Adam([torch.zeros(1, requires_grad=True)])  # the first optimizer imports torch._dynamo (seconds): once, here
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()

    def work(member: int) -> None:
        torch.set_num_threads(1)
        try:
            if member == SIDE_JOB:
                queue.put(("side", member, _dumps(side_job())))
                return
            result = train_member(member, lambda n, of: queue.put(("progress", member, (n, of))),
                                  lambda c: queue.put(("checkpoint", member, _dumps(c))))
            queue.put(("done", member, _dumps(result)))
        except BaseException as e:  # noqa: BLE001 - reported to the parent, which raises
            queue.put(("error", member, f"{type(e).__name__}: {e}"))

    pending, running, side = ([SIDE_JOB] if side_job else []) + list(members), {}, None
    try:
        while pending or running:
            while pending and len(running) < workers:
                member = pending.pop(0)
                running[member] = ctx.Process(target=work, args=(member,), daemon=True)
                running[member].start()
            try:
                kind, member, payload = queue.get(timeout=1.0)
            except Empty:
                dead = [m for m, p in running.items() if p.exitcode not in (None, 0)]
                if dead:
                    raise RuntimeError(f"training {_job_name(dead[0])} died (exit code {running[dead[0]].exitcode})")
                continue
            if kind == "progress":
                report(member, *payload)
            elif kind == "checkpoint":
                ckpt.save(member, _loads(payload))
            elif kind == "done":
                ckpt.finish(member, *_loads(payload))
                running.pop(member).join()
            elif kind == "side":
                side = _loads(payload)
                running.pop(member).join()
            else:
                raise RuntimeError(f"training {_job_name(member)} failed: {payload}")
    finally:
        for process in running.values():
            process.terminate()
    return side
