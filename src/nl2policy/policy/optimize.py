"""Optimize a lexical tree with PPO: tree -> DDT -> PPO -> discretized tree, checkpointed.

The training loop is in plain view in ``train_checkpointed``: learn one chunk of steps, save
the SB3 model, the step count and the episode curve so far, repeat. A killed run started
again with the same ``out`` folder loads the checkpoint and continues from the saved step.

What ``optimize_tree`` returns (``final_tree.json``) is never worse than the tree it was given:
the best of the initial tree and every checkpoint's tree (``keep_best``), where a checkpoint's
tree is the best of the readings of the trained DDT: its rounding; its distillation, the
dictionary tree that acts most like it in the states PPO visited lately (``distill``; measured
on highway, a start at 17.82 whose rounded trees never beat it came back at 19.53 read by
distillation: results/policy/history/distilled_reading_probe.md); and, with the domain's
``critic_reading`` knob, the tree PPO's critic favours there (``advantage``); the readings are
in ``readings``. With ``adopt_read_tree``, PPO continues from a checkpoint's tree wherever a
reading beat the rounding (``readings.tree_adopter``). Then, with ``polish``, a hill climb over
questions and actions from it (``polish``: on the exact model where the domain has one, climbing
from the start tree too and keeping the better end, else on common sampled scenes of its fast
simulator). PPO's own last tree (``last_tree.json``, its last checkpoint read the same ways),
the kept tree (``best_tree.json``) and the polished one (``polished_tree.json``) are written and
scored beside it, so the paper's DDT + PPO and each added step are reported separately.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Callable, NamedTuple, Optional

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from nl2policy.domains import get_domain
from nl2policy.domains.spec import Knobs
from nl2policy.policy.convert import has_raw_tests, tree_act_fn
from nl2policy.policy.distill import VisitedStates
from nl2policy.policy.keep_best import keep_best, tree_from_json, tree_scorer
from nl2policy.policy.readings import TreeScore, checkpoint_tree_score, tree_adopter
from nl2policy.policy.rollout import evaluate, tree_policy
from nl2policy.policy.sb3_policy import TreePPO, action_probs_fn, make_ppo, make_vec_env, soft_act_fn
from nl2policy.trees import Tree, tree_to_json

EVAL_SEED = 50_000  # evaluation episodes use seeds far from the training env's
CHECKPOINT = "checkpoint.zip"
STATE = "state.json"

Progress = Optional[Callable[[int, int], None]]


class OptimizeRefused(ValueError):
    """A run that cannot start as asked (the user's to fix: another --out, another flag); the
    commands catch only this, so a bug in training is never reported as bad input."""


def _write_atomically(path: Path, write: Callable[[Path], None]) -> None:
    """Write via a temporary file and a rename, so a run killed mid-write (a cancel, a kill)
    leaves the previous checkpoint whole rather than half a new one."""
    tmp = path.with_name(f"{path.stem}.tmp{path.suffix}")
    write(tmp)
    tmp.replace(path)


class EpisodeLog(BaseCallback):
    """Records (step, return) of every finished episode (from SB3's Monitor) and reports progress."""

    def __init__(self, episodes: list, total: int, progress: Progress) -> None:
        super().__init__()
        self.episodes, self.total, self.progress = episodes, total, progress

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.episodes.append((int(self.num_timesteps), float(info["episode"]["r"])))
        if self.progress:
            self.progress(min(int(self.num_timesteps), self.total), self.total)
        return True


def anneal(model: PPO, total: int) -> None:
    """Set the DDT's leaf temperature and node sharpness for the step `model` is at (see
    ``Anneal``); also at the end of training and after loading, so that the soft policy scored
    there is the same whether the run was resumed or not."""
    ddt = getattr(model.policy, "action_net", None)
    if not hasattr(ddt, "leaf_temperature"):
        return  # the MLP
    frac = min(1.0, model.num_timesteps / max(1, total))

    def line(start: float) -> float:  # 0 until `start` of the way in, then up to 1 at the end
        return max(0.0, (frac - start) / max(1e-9, 1.0 - start))

    if ddt.anneal_to != 1.0:
        ddt.leaf_temperature.fill_(1.0 + (ddt.anneal_to - 1.0) * line(ddt.anneal_from))
    if ddt.sharpen_to != 1.0:
        ddt.node_sharpness.fill_(1.0 + (ddt.sharpen_to - 1.0) * line(ddt.sharpen_from))


class Anneal(BaseCallback):
    """Before each rollout, set the DDT's leaf temperature on a line from 1 to its ``anneal_to``
    at `total` steps that starts ``anneal_from`` of the way in, and its node sharpness from 1 to
    its ``sharpen_to`` on a line that starts ``sharpen_from`` of the way in; a rollout and the
    update on it share one setting.

    Why the nodes can start late: PPO's tree improves late in a run (taxi Table 2's kept trees
    came from steps 134k-282k of 300k), and sharp nodes stop their questions moving. Measured
    with the nodes x10 over the last 30 % (results/policy/ablation_node_sharpen/): soft - tree
    -0.47..+0.15 but the kept tree the best depth-3 tree in 2 of 5 runs, against -0.03..-1.44
    and 4 of 5 with the leaves alone (ablation_leaf_anneal/)."""

    def __init__(self, total: int) -> None:
        super().__init__()
        self.total = total

    def _on_rollout_start(self) -> None:
        anneal(self.model, self.total)

    def _on_step(self) -> bool:
        return True


class Trained(NamedTuple):
    """What ``train_checkpointed`` hands back."""

    model: PPO
    episodes: list  # [(step, episode return)] of the training episodes, all sessions
    seconds: float  # training seconds, all sessions
    best: Optional[dict]  # the best checkpoint tree {"step", "tree", "score", "read"}; None without score_tree
    probes: list  # [{"step", **probe(model, tree)}] at step 0 and after every chunk; [] without probe
    last: Optional[dict]  # the last checkpoint's tree, read as `best` ({"step", "tree", "score", "read"}); None without score_tree


def train_checkpointed(model_factory: Callable[[], PPO], domain: str, seed: int, steps: int, run_dir: Path,
                       progress: Progress = None,
                       score_tree: Optional[TreeScore] = None,
                       simulator: str = "fast", probe: Optional[Callable[[PPO, Optional[dict]], dict]] = None,
                       checkpoints: int = 10, adopt: Optional[Callable[[PPO, Tree], None]] = None) -> Trained:
    """Train to `steps` env steps in about `checkpoints` chunks, checkpointing into `run_dir`
    after each; resumes a saved run.

    With `score_tree`, the model's tree (read with PPO's latest rollouts, ``distill.VisitedStates``)
    is scored after every chunk and the best one kept (``{"step", "tree", "score", "read"}``; the initial actor's tree counts as step 0). With `probe`,
    its measurements of the model (Table 2: the exact return of the policy a method hands
    back) are recorded at step 0 and after every chunk, so a curve of them survives resumes; it is
    given the checkpoint's tree as read above (None without `score_tree`), so what it scores is
    the tree a user would get from that checkpoint.

    With `adopt` (``readings.tree_adopter``), wherever a checkpoint's tree was read by another reading than
    the DDT's own rounding (it scored higher), PPO continues from that tree: its DDT is set to
    act like it. The probe then measures the soft policy after the move, and records the one
    before it as ``soft_before_adopt``. Not after the last chunk: there is no training left, and
    the soft policy at the end is the one PPO trained."""
    # PPO here runs batch-of-one forward passes through tiny nets: extra intra-op threads only
    # contend (measured 25x slower with 2 threads on a busy 2-core machine), so use one.
    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    state_path, ckpt_path = run_dir / STATE, run_dir / CHECKPOINT
    d = get_domain(domain)
    trained_on = "fast" if simulator == "fast" and d.train_env_id is not None else "reference"
    if state_path.is_file() and ckpt_path.is_file():
        state = json.loads(state_path.read_text())
        recorded = state.get("simulator", "reference")  # runs from before the twin trained on the reference env
        if recorded != trained_on:
            raise OptimizeRefused(f"{run_dir} holds a run trained on the {recorded} simulator; resume it with "
                                  f"--simulator {recorded} or choose another --out")
        resumed_seed = seed + 1000 * (state["chunks"] + 1)
        model = TreePPO.load(ckpt_path, env=make_vec_env(domain, resumed_seed, simulator), device="cpu")
        model.set_random_seed(resumed_seed)  # load reseeds with the run's first seed: new episodes, not a replay
        episodes, seconds, chunks = [tuple(e) for e in state["episodes"]], state["seconds"], state["chunks"]
        best, probes, last = state.get("best_tree"), state.get("probes", []), state.get("last_tree")
        if score_tree is not None and (best is None or last is None):  # a checkpoint from before its run tracked trees
            tree_json, score, read = score_tree(model, None)
            last = {"step": int(model.num_timesteps), "tree": tree_json, "score": score, "read": read}
            best = best or last
    else:
        model, episodes, seconds, chunks = model_factory(), [], 0.0, 0
        best = last = None
        probes = []
        if score_tree is not None:
            tree_json, score, read = score_tree(model, None)
            best = last = {"step": 0, "tree": tree_json, "score": score, "read": read}
        if probe is not None:
            probes.append({"step": 0, **probe(model, last and last["tree"])})
    rollout = model.n_steps * model.n_envs
    chunk = rollout * max(1, steps // (checkpoints * rollout))
    total = -(-steps // rollout) * rollout  # PPO trains whole rollouts
    log, visited = EpisodeLog(episodes, total, progress), VisitedStates()
    while model.num_timesteps < steps:
        start = time.perf_counter()
        model.learn(min(chunk, steps - model.num_timesteps), callback=CallbackList([log, visited, Anneal(total)]),
                    reset_num_timesteps=False)
        seconds += time.perf_counter() - start
        chunks += 1
        if score_tree is not None:
            tree_json, score, read = score_tree(model, visited)
            last = {"step": int(model.num_timesteps), "tree": tree_json, "score": score, "read": read}
            if score > best["score"]:
                best = last
        entry = {"step": int(model.num_timesteps), **probe(model, last and last["tree"])} if probe is not None else None
        if adopt is not None and last is not None and last["read"] != "rounded" and model.num_timesteps < steps:
            adopt(model, tree_from_json(last["tree"]))
            last = {**last, "adopted": True}
            if entry is not None:
                entry = {**entry, "soft_before_adopt": entry["soft"], **probe(model, last["tree"])}
        if entry is not None:
            probes.append(entry)
        _write_atomically(ckpt_path, model.save)
        state = {"steps": int(model.num_timesteps), "seconds": seconds, "chunks": chunks, "episodes": episodes,
                 "best_tree": best, "last_tree": last, "probes": probes, "simulator": trained_on}
        _write_atomically(state_path, lambda path: path.write_text(json.dumps(state)))
    anneal(model, total)  # the end of the schedule (or, resumed, where the run stood)
    if progress:
        progress(total, total)
    return Trained(model, episodes, seconds, best, probes, last)


def rolling_mean(returns: list[float], window: int) -> np.ndarray:
    """Mean of the last `window` episodes after each episode (fewer at the start)."""
    r = np.asarray(returns, dtype=float)
    if len(r) == 0:
        return r
    cumulative = np.concatenate([[0.0], np.cumsum(r)])
    idx = np.arange(1, len(r) + 1)
    lo = np.maximum(0, idx - window)
    return (cumulative[idx] - cumulative[lo]) / (idx - lo)


def write_curve(episodes: list, window: int, out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [s for s, _ in episodes]
    returns = [r for _, r in episodes]
    rolling = rolling_mean(returns, window)
    with open(out / "curve.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["episode", "step", "return", f"rolling_mean_{window}"])
        for i, (s, r, m) in enumerate(zip(steps, returns, rolling)):
            writer.writerow([i + 1, s, r, f"{m:.4f}"])
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(steps, returns, ".", ms=2, alpha=0.3, label="episode return")
    ax.plot(steps, rolling, label=f"rolling mean ({window} episodes)")
    ax.set_xlabel("env steps")
    ax.set_ylabel("episode return")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "curve.png", dpi=120)
    plt.close(fig)


def optimize_tree(domain: str, tree: Tree, steps: int, seed: int, out: Path, progress: Progress = None,
                  eval_episodes: Optional[int] = None, polish: Optional[bool] = None,
                  simulator: str = "fast", knobs: Optional[Knobs] = None) -> dict:
    """PPO from the tree-initialized DDT, then keep-best and (`polish`, default: where the
    domain has an exact model) the polish; writes initial_tree.json, last_tree.json,
    best_tree.json, [polished_tree.json,] final_tree.json (what is returned), curve.csv,
    curve.png and summary.json into `out` and returns the summary (see module doc). `knobs`: the
    domain's, changed for an experiment's training (PPO, the DDT, the readings, adoption); trees
    are still scored and polished with the domain's own knobs."""
    from nl2policy.policy.polish import can_polish, polish_kept

    d = get_domain(domain)
    knobs = knobs or d.knobs
    polish = can_polish(domain) if polish is None else polish
    if polish and not can_polish(domain):
        raise OptimizeRefused(f"--polish needs an exact model or a fast simulator with polish knobs; {domain} has neither")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tree_path = out / "initial_tree.json"
    if (out / STATE).is_file() and tree_path.is_file() and json.loads(tree_path.read_text()) != tree_to_json(tree):
        raise OptimizeRefused(f"{out} holds a checkpoint of a run from a different tree; choose another --out")
    tree_path.write_text(json.dumps(tree_to_json(tree), indent=2))
    scorer, rule = tree_scorer(domain)
    model, episodes, seconds, best, _, last = train_checkpointed(
        lambda: make_ppo(domain, "tree_ddt", seed, tree, simulator=simulator, knobs=knobs), domain, seed, steps, out,
        progress, checkpoint_tree_score(domain, True, scorer, knobs.critic_reading), simulator,
        adopt=tree_adopter(domain, knobs) if knobs.adopt_read_tree else None)
    last_tree = tree_from_json(last["tree"])  # PPO's own tree at the end, read as every checkpoint's
    (out / "last_tree.json").write_text(json.dumps(tree_to_json(last_tree), indent=2))
    start = time.perf_counter()
    initial_score = scorer(tree)
    kept, kept_score, kept_from = keep_best(tree, initial_score, best)
    (out / "best_tree.json").write_text(json.dumps(tree_to_json(kept), indent=2))
    select_seconds = time.perf_counter() - start
    final_tree, returned = kept, f"kept {kept_from}"
    polished, polished_from = None, None
    if polish and not has_raw_tests(kept):
        polished, polished_from = polish_kept(domain, kept, tree)
        (out / "polished_tree.json").write_text(json.dumps(tree_to_json(polished.tree), indent=2))
        if polished.value > kept_score:
            final_tree, returned = polished.tree, "polished"
    (out / "final_tree.json").write_text(json.dumps(tree_to_json(final_tree), indent=2))
    window = knobs.rolling_window
    write_curve(episodes, window, out, f"{domain}: PPO from the tree-initialized DDT (seed {seed})")
    n = eval_episodes or knobs.eval_episodes
    rolling = rolling_mean([r for _, r in episodes], window)
    returns: dict[Tree, float] = {}  # the final, kept and last trees are often one tree: evaluate it once

    def mean_return(t: Tree) -> float:
        if t not in returns:
            returns[t] = evaluate(domain, tree_act_fn(domain, t), n, EVAL_SEED).mean_return
        return returns[t]

    summary = {
        "domain": domain, "seed": seed, "steps": int(model.num_timesteps), "seconds": round(seconds, 2),
        "trained_on": d.train_env_id if simulator == "fast" and d.train_env_id else d.env_id,
        "evaluated_on": d.env_id, "eval_episodes": n, "eval_seed": EVAL_SEED, "returned": returned,
        "initial_mean_return": evaluate(domain, tree_policy(domain, tree), n, EVAL_SEED).mean_return,
        "final_mean_return": mean_return(final_tree),
        # the tree PPO handed back before any polish (keep-best), on the same episodes
        "kept_mean_return": mean_return(kept),
        "last_tree_mean_return": mean_return(last_tree),
        "final_soft_ddt_return": evaluate(domain, soft_act_fn(model, deterministic=False), n, EVAL_SEED).mean_return,
        "final_tree_has_raw_tests": has_raw_tests(final_tree),
        "training_episodes": len(episodes), "rolling_window": window,
        "first_rolling_return": float(rolling[min(window, len(rolling)) - 1]) if len(rolling) else None,
        "last_rolling_return": float(rolling[-1]) if len(rolling) else None,
        "keep_best": {"scored_by": rule, "initial_score": initial_score, "best_checkpoint_score": best["score"],
                      "best_checkpoint_step": best["step"], "best_checkpoint_read": best.get("read", "rounded"),
                      "last_checkpoint_read": last.get("read", "rounded"),
                      "kept": kept_from, "kept_score": kept_score,
                      "seconds": round(select_seconds, 2)},
    }
    # PPO's own discretization loss: its last tree (the better reading) against the soft DDT it came from
    summary["discretization_gap"] = summary["last_tree_mean_return"] - summary["final_soft_ddt_return"]
    if polished is not None:
        summary["polish"] = {"from": polished_from, "start_score": polished.start_value, "score": polished.value, "rounds": polished.rounds,
                             "candidates_scored": polished.candidates_scored, "seconds": round(polished.seconds, 2)}
    if d.exact is not None:  # exact expected returns of every tree above
        summary["exact_initial_tree"] = initial_score
        summary["exact_last_tree"] = float(d.exact.expected_return(tree_act_fn(domain, last_tree)))
        summary["exact_soft_ddt"] = d.exact.expected_return_mixed(action_probs_fn(model))
        summary["exact_discretization_gap"] = summary["exact_last_tree"] - summary["exact_soft_ddt"]
        summary["exact_best_tree"], summary["best_tree_step"] = kept_score, best["step"] if kept_from == "checkpoint" else 0
        if polished is not None:
            summary["exact_polished_tree"] = polished.value
        summary["exact_final_tree"] = float(d.exact.expected_return(tree_act_fn(domain, final_tree)))
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary
