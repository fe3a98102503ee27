"""How closely the highway twin follows highway-env: the fidelity table of the twin's claim.

Two measurements, both on the random policy and on corpus trees spread over the return range:

1. **Same distribution** (unpaired): each simulator draws its own scenes; mean return, crash
   rate, mean forward speed and the share of decisions in the right lane over `--episodes`
   episodes each, with standard errors, and the rank correlation of the policies' returns.
2. **Same scene** (paired), both ways: `--paired-episodes` twin scenes are copied into
   highway-env (``scenes.copy_scene_to``) and both run the policy from there; and every
   one of highway-env's own `--episodes` episodes is replayed in the twin from highway-env's
   scene (``copy_scene_from``). The share of episodes whose return agrees to 1e-6, and the
   crash rate of the replays against highway-env's on the very same episodes.

The trees are chosen by the twin alone, on screening episodes whose seeds the evaluation
never uses: every distinct corpus tree is run for `--screen-episodes` episodes and the trees
at evenly spaced quantiles of that return are kept.

highway-env episodes run in worker processes, in chunks recorded in ``<out>/fidelity_runs.jsonl``
as they finish, so a killed run picks up where it stopped when run again.

    .venv/bin/python -m experiments.highway_fidelity --out results/highway
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np
import typer
from rich.console import Console
from rich.progress import Progress
from scipy.stats import spearmanr

from nl2policy.data import corpus_dir
from nl2policy.domains import get_domain
from nl2policy.domains.highway.env import META_ACTION, HighwayFeatures
from nl2policy.domains.highway.scenes import copy_scene_from, copy_scene_to
from nl2policy.domains.highway.twin import HighwayTwin
from nl2policy.domains.highway.vec import twin_episodes
from experiments.grid import Job, normalize_ray_flag, ray_failure, ray_option_help, run_jobs
from nl2policy.trees import parse_tree, tree_to_json

SCREEN_SEED = 900_000  # screening episodes: far from the evaluation seeds
PAIRED_SEED = 500_000
RUNS = "fidelity_runs.jsonl"
console = Console()


def corpus_trees() -> list[dict]:
    """Distinct highway trees of the corpus's first round (the writers' own trees), as JSON."""
    seen, trees = set(), []
    for line in (corpus_dir() / "highway.jsonl").read_text().splitlines():
        if line.strip():
            tree = json.loads(line)["tree"]
            key = json.dumps(tree, sort_keys=True)
            if key not in seen:
                seen.add(key)
                trees.append(tree)
    return trees


def batch_policy(tree: Optional[dict], seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """A tree's actions for a batch of feature rows; None is the uniform random policy."""
    domain = get_domain("highway")
    if tree is None:
        rng = np.random.default_rng(seed)
        return lambda x: rng.integers(0, len(domain.actions), len(x))
    parsed = parse_tree(tree, domain.vocab)
    return lambda x: domain.tree_actions(parsed, x)


def choose_trees(count: int, screen_episodes: int) -> list[dict]:
    """`count` corpus trees at evenly spaced quantiles of their twin return (screening seeds)."""
    trees = corpus_trees()
    returns = np.array([twin_episodes(batch_policy(t, 0), screen_episodes, SCREEN_SEED)["return"].mean()
                        for t in trees])
    order = np.argsort(returns, kind="stable")
    picks = np.unique(np.round(np.linspace(0, len(trees) - 1, count)).astype(int))
    return [trees[order[p]] for p in picks]


def highway_env_chunk(policy: int, tree: Optional[dict], first: int, count: int, seed: int) -> dict:
    """Episodes seed+first .. seed+first+count-1 of one policy in highway-env (a worker's job)."""
    env = HighwayFeatures()
    act = batch_policy(tree, seed + first)
    rows = []
    for episode in range(first, first + count):
        obs, _ = env.reset(seed=seed + episode)
        rows.append(_run_highway_env(env, obs, act))
    env.close()
    return {"kind": "unpaired", "policy": policy, "first": first, "count": count, "episodes": rows}


def replay_chunk(policy: int, tree: Optional[dict], first: int, count: int, seed: int) -> dict:
    """One highway_env_chunk's episodes replayed in the twin from highway-env's scenes."""
    return {"kind": "replay", "policy": policy, "first": first, "count": count,
            "episodes": replay_in_twin(tree, first, count, seed)}


def paired_chunk(policy: int, tree: Optional[dict], first: int, count: int, seed: int) -> dict:
    """Twin scenes first .. first+count-1 of PAIRED_SEED, each run in the twin and in highway-env."""
    env = HighwayFeatures()
    twin_all = HighwayTwin(first + count, seed=seed)  # the scenes, fixed by the seed and the chunk
    rows = []
    for episode in range(first, first + count):
        twin = HighwayTwin(1)
        for name in ("x", "y", "heading", "speed", "target_speed", "delta", "timer", "lane", "target_lane"):
            getattr(twin, name)[0] = getattr(twin_all, name)[episode]
        env.reset(seed=seed + episode)
        copy_scene_to(env, twin, 0)
        # Each simulator gets its own copy of the policy, so a random policy draws the same actions in both.
        highway = _run_highway_env(env, twin.features()[0], batch_policy(tree, seed + episode))
        act = batch_policy(tree, seed + episode)
        total, done = 0.0, False
        obs = twin.features()
        while not done:
            reward, terminated, truncated = twin.step(np.asarray([META_ACTION[int(act(obs)[0])]]))
            obs = twin.features()
            total += float(reward[0])
            done = bool(terminated[0] or truncated[0])
        rows.append({"highway_env": highway["return"], "twin": total})
    env.close()
    return {"kind": "paired", "policy": policy, "first": first, "count": count, "episodes": rows}


def replay_in_twin(tree: Optional[dict], first: int, count: int, seed: int) -> list[dict]:
    """highway-env's episodes seed+first .. seed+first+count-1, replayed in the twin from
    highway-env's own scenes (``copy_scene_from``) with the policy as highway_env_chunk ran it
    (a random policy draws from the same generator, episode after episode)."""
    env = HighwayFeatures()
    act = batch_policy(tree, seed + first)
    rows = []
    for episode in range(first, first + count):
        env.reset(seed=seed + episode)
        twin = HighwayTwin(1)
        copy_scene_from(env, twin, 0)
        obs, total, steps, done = twin.features(), 0.0, 0, False
        while not done:
            reward, terminated, truncated = twin.step(np.asarray([META_ACTION[int(act(obs)[0])]]))
            obs = twin.features()
            total, steps = total + float(reward[0]), steps + 1
            done = bool(terminated[0] or truncated[0])
        rows.append({"return": total, "crashed": bool(twin.crashed[0, 0]), "steps": steps})
    env.close()
    return rows


def _run_highway_env(env: HighwayFeatures, obs: np.ndarray, act: Callable) -> dict:
    total, steps, speed, right, done, crashed = 0.0, 0, 0.0, 0, False, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(int(act(obs[None, :])[0]))
        car = env.highway.vehicle
        total += float(reward)
        steps += 1
        speed += float(car.speed * np.cos(car.heading))
        right += int(obs[4] == 1.0)
        crashed = bool(info["crashed"])
        done = terminated or truncated
    return {"return": total, "crashed": crashed, "steps": steps, "mean_speed": speed / steps,
            "right_lane": right / steps}


def _stats(values: np.ndarray) -> tuple[float, float]:
    values = np.asarray(values, dtype=np.float64)
    return float(values.mean()), float(values.std(ddof=1) / math.sqrt(len(values)))


def summarize(policies: list[Optional[dict]], runs: list[dict], twin: list[dict]) -> list[dict]:
    rows = []
    for p, tree in enumerate(policies):
        hw = [e for r in runs if r["kind"] == "unpaired" and r["policy"] == p for e in r["episodes"]]
        paired = [e for r in runs if r["kind"] == "paired" and r["policy"] == p for e in r["episodes"]]
        row: dict[str, Any] = {"policy": "random" if tree is None else f"tree {p}", "tree": tree}
        for name, source in (("highway_env", {k: np.array([e[k] for e in hw]) for k in hw[0]}), ("twin", twin[p])):
            for metric in ("return", "crashed", "mean_speed", "right_lane"):
                mean, se = _stats(source[metric])
                row[f"{name}_{metric}"], row[f"{name}_{metric}_se"] = mean, se
            row[f"{name}_episodes"] = len(source["return"])
        diff = row["twin_return"] - row["highway_env_return"]
        se_diff = math.hypot(row["twin_return_se"], row["highway_env_return_se"])
        row["return_diff"] = diff
        row["return_diff_se"] = se_diff
        row["return_within"] = abs(diff) <= max(0.05 * abs(row["highway_env_return"]), 2 * se_diff)
        crash_diff = row["twin_crashed"] - row["highway_env_crashed"]
        row["crash_diff_points"] = 100 * crash_diff
        row["crash_diff_se_points"] = 100 * math.hypot(row["twin_crashed_se"], row["highway_env_crashed_se"])
        replay = [e for r in runs if r["kind"] == "replay" and r["policy"] == p for e in r["episodes"]]
        if replay:  # matched to highway-env's episodes by seed
            hw_by_first = {r["first"]: r["episodes"] for r in runs if r["kind"] == "unpaired" and r["policy"] == p}
            rp_by_first = {r["first"]: r["episodes"] for r in runs if r["kind"] == "replay" and r["policy"] == p}
            pairs = [(h, t) for first in sorted(rp_by_first) for h, t in zip(hw_by_first[first], rp_by_first[first])]
            row["replay_episodes"] = len(pairs)
            row["replay_identical"] = float(np.mean([abs(h["return"] - t["return"]) <= 1e-6 for h, t in pairs]))
            row["replay_crashed"] = float(np.mean([t["crashed"] for _, t in pairs]))
            row["replay_crash_diff_points"] = 100 * (row["replay_crashed"] - float(np.mean([h["crashed"] for h, _ in pairs])))
            row["replay_return"] = float(np.mean([t["return"] for _, t in pairs]))
        if paired:
            gaps = np.array([abs(e["twin"] - e["highway_env"]) for e in paired])
            row["paired_episodes"] = len(paired)
            row["paired_identical"] = float(np.mean(gaps <= 1e-6))
            row["paired_max_gap"] = float(gaps.max())
        rows.append(row)
    return rows


def write_tables(rows: list[dict], meta: dict, out: Path) -> None:
    hw = [r["highway_env_return"] for r in rows]
    tw = [r["twin_return"] for r in rows]
    rho = float(spearmanr(hw, tw).statistic)
    meta = {**meta, "spearman_returns": rho}
    (out / "fidelity.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    lines = [
        "# Highway twin against highway-env",
        "",
        f"Made by: `{meta['command']}`  ",
        f"On: {meta['made']}; {meta['highway_env_episodes']} episodes a policy in each simulator "
        f"(highway-env seeds {meta['seed']}.., twin seed {meta['seed']}), paired check on "
        f"{meta['paired_episodes']} twin scenes a policy; trees chosen by twin return on "
        f"{meta['screen_episodes']} screening episodes (seed {SCREEN_SEED}).",
        "",
        "Return: mean episode return (standard error). Within: |twin - highway-env| at most 5% of "
        "highway-env's mean or 2 standard errors of the difference, whichever is wider. Crash, "
        "speed (mean forward m/s over decisions) and right lane (share of decisions) as means. "
        f"Same scene: share of episodes whose returns agree to 1e-6, from the twin's scenes "
        f"({meta['paired_episodes']} a policy) and from highway-env's own scenes (its {meta['highway_env_episodes']} "
        "episodes replayed in the twin), with the replays' crash rate minus highway-env's on those same episodes "
        "(points).",
        "",
        "| policy | highway-env return | twin return | within | crash % hw / twin (diff ± se) | speed hw / twin "
        "| right lane hw / twin | same scene: twin's / highway-env's scenes (crash diff) |",
        "|---|---:|---:|:-:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['policy']} | {r['highway_env_return']:.2f} ({r['highway_env_return_se']:.2f}) "
            f"| {r['twin_return']:.2f} ({r['twin_return_se']:.2f}) | {'yes' if r['return_within'] else 'no'} "
            f"| {100 * r['highway_env_crashed']:.1f} / {100 * r['twin_crashed']:.1f} "
            f"({r['crash_diff_points']:+.1f} ± {r['crash_diff_se_points']:.1f}) "
            f"| {r['highway_env_mean_speed']:.2f} / {r['twin_mean_speed']:.2f} "
            f"| {r['highway_env_right_lane']:.3f} / {r['twin_right_lane']:.3f} "
            f"| {100 * r.get('paired_identical', float('nan')):.0f}% / {100 * r.get('replay_identical', float('nan')):.1f}% "
            f"({r.get('replay_crash_diff_points', float('nan')):+.1f}) |")
    within = sum(r["return_within"] for r in rows)
    replay2 = sum(abs(r.get("replay_crash_diff_points", float("inf"))) <= 2 for r in rows)
    crash2 = sum(abs(r["crash_diff_points"]) <= 2 for r in rows)
    crash_se = sum(abs(r["crash_diff_points"]) <= 2 * r["crash_diff_se_points"] for r in rows)
    lines += [
        "",
        f"Returns within tolerance: {within} of {len(rows)}. Crash rates within 2 points: {crash2} of "
        f"{len(rows)}; within 2 standard errors of the difference: {crash_se} of {len(rows)}. "
        f"Spearman rank correlation of the policies' returns: {rho:.3f}. On the same episodes (highway-env's "
        f"scenes replayed in the twin) crash rates agree within 2 points for {replay2} of {len(rows)}.",
        "",
        "Trees, in table order:",
        "",
    ]
    for r in rows:
        if r["tree"] is not None:
            lines.append(f"- {r['policy']}: `{json.dumps(r['tree'])}`")
    (out / "fidelity.md").write_text("\n".join(lines) + "\n")


def main(
    out: Path = typer.Option(Path("results/highway"), help="folder for fidelity.md/json and the run log"),
    episodes: int = typer.Option(500, min=2, help="episodes a policy in each simulator"),
    paired_episodes: int = typer.Option(50, min=0, help="twin scenes a policy replayed in highway-env"),
    trees: int = typer.Option(12, min=2, help="corpus trees, spread over the return range"),
    screen_episodes: int = typer.Option(200, min=1, help="twin episodes a tree when choosing trees"),
    seed: int = typer.Option(0, min=0, help="first highway-env seed; the twin's seed"),
    workers: int = typer.Option(2, min=1, help="highway-env worker processes"),
    chunk: int = typer.Option(25, min=1, help="highway-env episodes a job"),
    ray: Optional[str] = typer.Option(None, "--ray", help=ray_option_help()),
) -> None:
    """Fidelity of the highway twin against highway-env (resumable; see the module docstring)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        log = out / RUNS
        log.touch()
    except OSError as error:
        raise SystemExit(f"error: cannot write to {out}: {error.strerror}") from None
    command = (f".venv/bin/python -m experiments.highway_fidelity --out {out} --episodes {episodes} "
               f"--paired-episodes {paired_episodes} --trees {trees} --screen-episodes {screen_episodes} "
               f"--seed {seed} --workers {workers} --chunk {chunk}")
    policies: list[Optional[dict]] = [None] + choose_trees(trees, screen_episodes)
    runs = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    runs = [r for r in runs if r.get("command") == command]
    done = {(r["kind"], r["policy"], r["first"]) for r in runs}
    jobs = [("unpaired", p, first, min(chunk, episodes - first))
            for p in range(len(policies)) for first in range(0, episodes, chunk)]
    jobs += [("paired", p, first, min(chunk, paired_episodes - first))
             for p in range(len(policies)) for first in range(0, paired_episodes, chunk)]
    jobs += [("replay", p, first, min(chunk, episodes - first))
             for p in range(len(policies)) for first in range(0, episodes, chunk)]
    todo = [j for j in jobs if (j[0], j[1], j[2]) not in done]
    console.print(f"{len(policies)} policies; {len(jobs) - len(todo)} of {len(jobs)} highway-env jobs done before")
    started = time.perf_counter()
    fns = {"unpaired": highway_env_chunk, "paired": paired_chunk, "replay": replay_chunk}
    grid = [Job(f"{kind} {p} {first}", fns[kind], {"policy": p, "tree": policies[p], "first": first, "count": count,
                                                   "seed": PAIRED_SEED + seed if kind == "paired" else seed})
            for kind, p, first, count in todo]
    with Progress(console=console) as bar:
        task = bar.add_task("highway-env episodes" + (f" on Ray ({ray})" if ray else ""), total=sum(j[3] for j in todo))

        def record(job: Job, chunk_result: dict) -> None:
            result = {**chunk_result, "command": command}
            with log.open("a") as handle:
                handle.write(json.dumps(result) + "\n")
            runs.append(result)
            bar.advance(task, job.kwargs["count"])

        try:
            run_jobs(grid, record, ray=ray, processes=workers)
        except Exception as exc:  # Ray's own failures are one line, not a traceback
            reason = ray_failure(exc)
            if reason is None:
                raise
            raise SystemExit(f"error: {reason}") from None
    twin = [twin_episodes(batch_policy(tree, seed), episodes, seed) for tree in policies]
    meta = {"command": command, "made": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "highway_env_episodes": episodes, "paired_episodes": paired_episodes, "seed": seed,
            "screen_episodes": screen_episodes, "python": platform.python_version(),
            "highway_env_seconds_this_run": round(time.perf_counter() - started, 1)}
    write_tables(summarize(policies, runs, twin), meta, out)
    console.print(f"wrote {out / 'fidelity.md'}")


if __name__ == "__main__":
    cli = typer.Typer(add_completion=False)
    cli.command()(main)
    cli(args=normalize_ray_flag(sys.argv[1:]))
