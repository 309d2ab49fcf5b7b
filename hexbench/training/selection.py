"""Choosing a training run's checkpoint on held-out episodes (`hexbench checkpoints select`).

What training logs (the stochastic policy's success at its own curriculum level) does not say
which checkpoint's deterministic policy walks best, and trying checkpoints on the protocol's
episodes would be selecting on the test set. So every checkpoint of a run is scored here by its
deterministic policy (what `hexbench run` evaluates) on held-out episodes:

  - the protocol's rules (step limit, corridor, fall, stall; observation noise on) at fixed
    selection levels per terrain, near where the open-loop CPG starts to fail (SELECTION_LEVELS);
  - seeds from the "heldout" namespace: episode_seed("heldout", terrain, level, i), which no
    protocol version uses (protocol seeds are derived from "v1", "v2", ...).

Rank of a checkpoint: the 95% Wilson lower bound of its held-out success rate, then its mean forward
progress [m] with each episode capped at the goal distance, then more episodes, then fewer env
steps. Episodes are kept in RUN_DIR/selection.json by checkpoint sha256, so selecting again only
plays what is missing (new checkpoints, or more episodes for the front-runners with --top); `hexbench checkpoints publish --checkpoint heldout` ships
the best-scored one.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from hexbench.errors import HexbenchError
from hexbench.suite.numerics import use_controller_math
from hexbench.training.runs import read_run
from hexbench.training.settings import TrainError, load_baseline_config

HELDOUT_NAMESPACE = "heldout"
SELECTION_FILE = "selection.json"
SAVE_EVERY_S = 60.0  # selection.json is rewritten at least this often during a long selection
# Per terrain, two levels where the open-loop CPG's success falls off (leaderboard/cpg.json): rough and
# stairs in the upper half of paper Table 4; on slopes the CPG passes every Table 4 level, so its top
# level and the 18 deg headroom level (CPG 85%). And one easy level: selecting on the hard two alone
# chose a stairs policy that passes 8 cm but drifts out of the corridor on 2 cm steps in 5 of 20
# protocol episodes (the open-loop CPG: 0 of 20).
SELECTION_LEVELS: dict[str, tuple[float, ...]] = {"rough": (5.0, 9.0, 11.0), "slopes": (10.0, 15.0, 18.0),
                                                  "stairs": (3.0, 7.0, 8.0)}


class SelectionError(HexbenchError):
    """Bad selection input (run directory, levels); the message is one line."""


@dataclass(frozen=True)
class EpisodeOutcome:
    success: bool
    progress_m: float
    end_reason: str


def heldout_seeds(terrain: str, level: float, episodes: int) -> list[int]:
    from hexbench.suite.tasks import episode_seed

    return [episode_seed(HELDOUT_NAMESPACE, terrain, level, i) for i in range(episodes)]


def _run_config(run: dict):
    """The baseline CONFIG a run was trained with (its file's dataclass, with the run's values)."""
    try:
        base = load_baseline_config(Path(run["baseline_file"]))
    except TrainError as e:
        raise SelectionError(str(e)) from None
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in run["config"].items()}
    return replace(base, **values)


def play_episode(policy, config, terrain: str, level: float, seed: int) -> EpisodeOutcome:
    """One deterministic episode of `policy` under the protocol's rules at (terrain, level), through the
    one episode loop (hexbench.suite.rollout)."""
    from hexbench.agents.policy import PolicyController, heading_hold
    from hexbench.suite.rollout import LocalActor, play
    from hexbench.suite.tasks import load_suite

    suite = load_suite()
    task = suite.task(terrain, level)
    actor = LocalActor(PolicyController(config.action_mode, policy,
                                        decision_interval_steps=getattr(config, "decision_interval_steps", 1),
                                        heading_hold=heading_hold(config)))
    row = play(task, seed, actor, where="policy", residual_scale=config.residual_scale).row
    return EpisodeOutcome(row["success"], float(row["progress_m"]), row["end_reason"])


def score_job(job: tuple) -> tuple[str, float, int, dict]:
    """One held-out episode: job = (run.json dict, run directory, checkpoint entry, level, seed);
    returns (checkpoint sha256, level, seed, outcome or {"error": one line})."""
    import torch

    from hexbench.agents.policy import load_policy
    from hexbench.artifacts.manifest import CheckpointError

    torch.set_num_threads(1)
    run, run_dir, ckpt, level, seed = job
    config = _run_config(run)
    try:
        policy = load_policy(config, Path(run_dir) / ckpt["file"], ckpt["sha256"])
    except CheckpointError as e:
        return ckpt["sha256"], level, seed, {"error": str(e)}
    out = play_episode(policy, config, run["terrain"], level, seed)
    return ckpt["sha256"], level, seed, {"success": out.success, "progress_m": round(out.progress_m, 4),
                                         "end_reason": out.end_reason}


def checkpoint_score(entry: dict, goal_distance_m: float) -> tuple[float, float, int]:
    """How a checkpoint ranks: (95% Wilson lower bound of its held-out success rate, mean progress [m]
    with each episode capped at the goal distance, episodes played). The lower bound makes 19 of 20
    outrank 3 of 3, so a checkpoint lucky on few episodes does not win."""
    from hexbench.suite.scoring import wilson_interval

    episodes = entry["episodes"]
    if not episodes:
        return -1.0, -math.inf, 0
    wins = sum(e["success"] for e in episodes)
    progress = [min(e["progress_m"], goal_distance_m) for e in episodes]
    return wilson_interval(wins, len(episodes))[0], float(np.mean(progress)), len(episodes)


def rank_key(table: dict, sha256: str) -> tuple:
    """Sort key of a scored checkpoint in a selection table: its score, then fewer env steps."""
    entry = table["checkpoints"][sha256]
    return checkpoint_score(entry, table["goal_distance_m"]), -entry["env_steps"]


def select(run_dir: Path, *, episodes: int = 3, levels: tuple[float, ...] | None = None, stride: int = 1,
           min_env_steps: int | None = None, max_env_steps: int | None = None, top: int | None = None,
           workers: int = 1, progress: bool = True) -> dict:
    """Play held-out episodes for the run's checkpoints until each chosen one has `episodes` per level.

    Chosen: every `stride`-th checkpoint and the last of those between `min_env_steps` and
    `max_env_steps` (a run that learns late need not score its early checkpoints); with `top`, only
    the `top` best-scored so far (to give the front-runners more episodes). Episodes already in
    RUN_DIR/selection.json are kept (a change of levels starts afresh). Returns the table it writes.
    """
    from hexbench.suite.tasks import load_suite

    run_dir = Path(run_dir)
    run = read_run(run_dir)
    if run is None:
        raise SelectionError(f"{run_dir}: no run.json (not a training run directory)")
    ckpts = run.get("checkpoints") or []
    if not ckpts:
        raise SelectionError(f"{run_dir}: run has no checkpoints yet")
    terrain = run["terrain"]
    levels = tuple(levels) if levels else SELECTION_LEVELS[terrain]
    try:  # selection levels are protocol levels; the suite names the valid ones
        tasks = [load_suite().task(terrain, lv) for lv in levels]
    except ValueError as e:
        raise SelectionError(str(e)) from None
    if episodes < 1 or stride < 1 or workers < 1 or (top is not None and top < 1):
        raise SelectionError("--episodes, --stride, --top and --workers must be >= 1")

    path = run_dir / SELECTION_FILE
    table = json.loads(path.read_text()) if path.exists() else {}
    if table.get("levels") != list(levels):
        table = {"namespace": HELDOUT_NAMESPACE, "levels": list(levels), "checkpoints": {}}
    table["goal_distance_m"] = tasks[0].goal_distance_m
    scores = table["checkpoints"]

    low, high = min_env_steps or 0, max_env_steps if max_env_steps is not None else math.inf
    in_window = [c for c in ckpts if low <= c["env_steps"] <= high]
    if not in_window:
        window = " and ".join(f"{op} {n}" for op, n in ((">=", min_env_steps), ("<=", max_env_steps)) if n is not None)
        raise SelectionError(f"{run_dir}: no checkpoint at {window} env steps "
                             f"(checkpoints run from {ckpts[0]['env_steps']} to {ckpts[-1]['env_steps']})")
    chosen = _chosen(run_dir, in_window, stride, top, table)
    jobs = []
    for c in chosen:
        have = {(e["level"], e["seed"]) for e in scores.get(c["sha256"], {}).get("episodes", [])}
        jobs += [(run, str(run_dir), c, lv, seed) for lv in levels for seed in heldout_seeds(terrain, lv, episodes)
                 if (lv, seed) not in have]
        scores.setdefault(c["sha256"], {"file": c["file"], "env_steps": c["env_steps"], "episodes": []})
    _play(jobs, f"held-out episodes ({len(chosen)} checkpoints)", workers, progress, path, table, run)
    _save(path, table, run)
    return table


def _chosen(run_dir: Path, ckpts: list[dict], stride: int, top: int | None, table: dict) -> list[dict]:
    """Every `stride`-th checkpoint and the last; with `top`, the `top` best-scored of those; all with files."""
    chosen = ckpts[::stride]
    if chosen[-1] is not ckpts[-1]:
        chosen.append(ckpts[-1])
    if top is not None:
        ranked = sorted((c for c in chosen if c["sha256"] in table["checkpoints"]),
                        key=lambda c: rank_key(table, c["sha256"]), reverse=True)
        chosen = ranked[:top]
    absent = [c for c in chosen if not (run_dir / c["file"]).is_file()]
    if absent:  # pruned, or trained on another machine and only the last checkpoints copied here
        present = [c["env_steps"] for c in ckpts if (run_dir / c["file"]).is_file()]
        where = f"files exist for {present[0]} to {present[-1]} env steps" if present else "no checkpoint file exists"
        raise SelectionError(f"{run_dir}: {len(absent)} chosen checkpoint(s) have no file (first: {absent[0]['file']}); "
                             f"{where}: choose them with --min-env-steps / --max-env-steps")
    return chosen


def _play(jobs: list[tuple], title: str, workers: int, progress: bool, path: Path, table: dict, run: dict) -> None:
    """Play the jobs' episodes (in `workers` processes) into the table, saving it every SAVE_EVERY_S."""
    from rich.progress import Progress

    scores = table["checkpoints"]
    with Progress(disable=not progress, transient=True) as bar:
        task = bar.add_task(title, total=len(jobs))
        # the arithmetic of `hexbench run`'s controller processes, so a checkpoint's held-out score is
        # the same on every x86-64 CPU (in this process it holds where nothing has multiplied yet)
        if workers == 1:
            use_controller_math()
            outcomes, pool = map(score_job, jobs), None
        else:
            pool = get_context("spawn").Pool(workers, initializer=use_controller_math)
            outcomes = pool.imap_unordered(score_job, jobs)
        try:
            last_save = time.monotonic()
            for sha, level, seed, outcome in outcomes:
                if "error" in outcome:
                    raise SelectionError(outcome["error"])
                scores[sha]["episodes"].append({"level": level, "seed": seed, **outcome})
                bar.advance(task)
                if time.monotonic() - last_save > SAVE_EVERY_S:  # an interrupted selection keeps its episodes
                    _save(path, table, run)
                    last_save = time.monotonic()
        finally:
            if pool is not None:
                pool.terminate()


def _save(path: Path, table: dict, run: dict) -> None:
    from hexbench.artifacts.files import write_json_atomic

    scores = table["checkpoints"]
    for entry in scores.values():
        entry["episodes"].sort(key=lambda e: (e["level"], e["seed"]))
    scored = [c for c in run["checkpoints"] if scores.get(c["sha256"], {}).get("episodes")]
    if scored:
        best = max(scored, key=lambda c: rank_key(table, c["sha256"]))
        table["best"] = {"file": best["file"], "env_steps": best["env_steps"], "sha256": best["sha256"]}
    write_json_atomic(path, table)


def heldout_best(run_dir: Path, run: dict) -> dict:
    """The run's checkpoint entry that `select` scored best; SelectionError if never selected."""
    path = Path(run_dir) / SELECTION_FILE
    if not path.exists():
        raise SelectionError(f"{run_dir}: no {SELECTION_FILE}; run `hexbench checkpoints select {run_dir}` first")
    best = json.loads(path.read_text()).get("best") or {}
    for c in run["checkpoints"]:
        if c["sha256"] == best.get("sha256"):
            return c
    raise SelectionError(f"{path}: its best checkpoint is not in run.json (stale selection); select again")


def selection_summary(run_dir: Path, sha256: str) -> dict | None:
    """How one checkpoint did on the run's held-out episodes, for the shipped-weights manifest
    (None if the run was never selected on or that checkpoint was not scored)."""
    path = Path(run_dir) / SELECTION_FILE
    if not path.exists():
        return None
    table = json.loads(path.read_text())
    scores = table["checkpoints"]
    if sha256 not in scores or not scores[sha256]["episodes"]:
        return None
    ranked = sorted((s for s in scores if scores[s]["episodes"]),
                    key=lambda s: rank_key(table, s), reverse=True)
    lower, progress_m, n = checkpoint_score(scores[sha256], table["goal_distance_m"])
    return {"by": "held-out episodes (hexbench.training.selection)", "levels": table["levels"], "episodes": n,
            "successes": sum(e["success"] for e in scores[sha256]["episodes"]),
            "success_rate_lower_95": round(lower, 3), "mean_progress_m": round(progress_m, 3),
            "rank": ranked.index(sha256) + 1, "checkpoints_scored": len(ranked),
            "best_env_steps": scores[ranked[0]]["env_steps"]}
