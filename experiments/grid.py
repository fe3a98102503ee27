"""Run an experiment grid's independent jobs here, one after another, or as Ray tasks.

The grids behind the tables (folds x repeats, methods x trees x seeds) are independent jobs
whose results the caller writes, in the job's order of completion, to the same files either
way. A job is a module-level function and its keyword arguments, so Ray can ship it to any
worker; it must depend only on its arguments (seeds included), not on which worker runs it.

``ray=None`` runs the jobs in this process. ``ray="local"`` starts an embedded Ray on this
machine (no setup, no dashboard); any other value is the address of a running cluster
(``ray start --head`` prints it), which the driver joins. Each job is one task that declares
``cpus`` CPUs; Ray retries a task whose worker died (``RETRIES``), and since every job resumes
from its own checkpoint or result file, a retry continues where the killed worker stopped and
running the command again skips what finished.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

LOCAL = "local"
RETRIES = 3  # a task whose worker process dies is started again this many times
REPO_ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Job:
    """One cell of a grid: `fn(**kwargs)`, named `name` in progress messages."""

    name: str
    fn: Callable[..., Any]
    kwargs: dict = field(default_factory=dict)
    cpus: int = 1


def ray_option_help() -> str:
    return ("Run the grid on Ray: 'local' starts an embedded Ray on this machine, an address "
            "(host:port from `ray start --head`) joins that cluster; one task per run, results in the same files")


def normalize_ray_flag(argv: list[str]) -> list[str]:
    """`--ray` given without a value means `--ray local` (Typer's options take no optional value)."""
    out = list(argv)
    for i, arg in enumerate(out):
        if arg == "--ray" and (i + 1 == len(out) or out[i + 1].startswith("-")):
            out.insert(i + 1, LOCAL)
            break
    return out


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail at once on a cluster address nothing answers at: ray.init would retry for minutes,
    printing its own C++ warnings, before giving up."""
    import socket

    host, _, port = address.split("://")[-1].rpartition(":")
    if not host or not port.isdigit():
        return  # not host:port (e.g. "auto"): Ray resolves it itself
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise ConnectionError(f"cannot reach a Ray cluster at {address}: {exc.strerror or exc}") from None


def _start_ray(address: str, cpus: Optional[int]) -> None:
    import ray

    if ray.is_initialized():
        return
    # workers import the project as the driver does: the package (installed) and the lab (repo root)
    path = os.pathsep.join(p for p in (str(REPO_ROOT), os.environ.get("PYTHONPATH", "")) if p)
    runtime_env = {"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}}
    if address != LOCAL:
        _check_reachable(address)
    if address == LOCAL:
        ray.init(num_cpus=cpus or os.cpu_count() or 1, include_dashboard=False, log_to_driver=False,
                 runtime_env=runtime_env, logging_level="ERROR", configure_logging=True)
    else:
        ray.init(address=address, log_to_driver=False, runtime_env=runtime_env, logging_level="ERROR")


def run_jobs(jobs: Sequence[Job], on_result: Callable[[Job, Any], None], ray: Optional[str] = None,
             cpus: Optional[int] = None, on_start: Optional[Callable[[Job], None]] = None,
             processes: int = 1) -> None:
    """Run `jobs`, calling `on_result(job, result)` in this process as each finishes (in order
    here; in order of completion on Ray or with `processes` > 1, forked worker processes on this
    machine). `cpus`: the local Ray's CPUs (default: all)."""
    if ray is None and processes <= 1:
        for job in jobs:
            if on_start:
                on_start(job)
            on_result(job, job.fn(**job.kwargs))
        return
    if ray is None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=processes, mp_context=multiprocessing.get_context("fork")) as pool:
            futures = {}
            for job in jobs:
                futures[pool.submit(job.fn, **job.kwargs)] = job
                if on_start:
                    on_start(job)
            for future in as_completed(futures):
                on_result(futures[future], future.result())
        return
    import ray as ray_lib

    owned = not ray_lib.is_initialized()  # a caller's own Ray (a benchmark's, a notebook's) stays up
    _start_ray(ray, cpus)
    pending = {}
    for job in jobs:
        task = ray_lib.remote(num_cpus=job.cpus, max_retries=RETRIES)(job.fn)
        pending[task.remote(**job.kwargs)] = job
        if on_start:
            on_start(job)
    try:
        while pending:
            done, _ = ray_lib.wait(list(pending), num_returns=1)
            for ref in done:
                job = pending.pop(ref)
                on_result(job, ray_lib.get(ref))
    finally:
        for ref in pending:  # an interrupted driver leaves no task running (no orphans)
            ray_lib.cancel(ref, force=True)
        if ray == LOCAL and owned:
            ray_lib.shutdown()


def ray_failure(exc: BaseException) -> Optional[str]:
    """A one-line reason when `exc` is Ray's (a task that failed after its retries, a cluster
    that cannot be reached), else None: the commands report it as bad input, not a traceback."""
    module = type(exc).__module__ or ""
    if module.startswith("ray") or isinstance(exc, ConnectionError):
        text = str(exc).strip().splitlines()
        return f"the Ray grid stopped: {type(exc).__name__}: {text[-1] if text else ''} (run the command again to resume)"
    return None

