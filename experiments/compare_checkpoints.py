"""Held-out head-to-head of checkpoints from different training runs.

`hexbench checkpoints select` ranks the checkpoints of one run. To choose between the best of two
runs, this plays each named checkpoint's deterministic policy on the same held-out seeds
(`hexbench.training.selection.heldout_seeds`, never a protocol seed) at the levels given, under the
protocol's rules, and prints successes per level and forward progress (mean and max over all its
episodes), which tells checkpoints apart where none arrives. Nothing is written to the runs'
selection.json. A level between suite levels (e.g. slopes 19.5) plays under the next suite level's
rules, with its own held-out seeds (levels.task_between): a diagnostic of thresholds, not a score.

    python experiments/compare_checkpoints.py training/RUN_A:ENV_STEPS training/RUN_B:ENV_STEPS \\
        --levels 5 7 9 11 --episodes 20 --workers 2
"""

from __future__ import annotations

import argparse
import json
from collections import Counter, defaultdict
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np
from levels import task_between

from hexbench.suite.tasks import load_suite
from hexbench.training.runs import checkpoint_at, read_run
from hexbench.training.selection import heldout_seeds
from hexbench.training.settings import TrainError, load_baseline_config


def parse_candidate(text: str) -> tuple[dict, Path, dict]:
    """'RUN_DIR:ENV_STEPS' -> (run.json, run directory, checkpoint entry)."""
    run_dir, _, steps = text.rpartition(":")
    run = read_run(Path(run_dir))
    if run is None:
        raise SystemExit(f"error: {run_dir}: no run.json (expected RUN_DIR:ENV_STEPS)")
    try:
        return run, Path(run_dir), checkpoint_at(Path(run_dir), run, steps)
    except TrainError as e:
        raise SystemExit(f"error: {e}") from None


def run_config(run: dict):
    """The baseline CONFIG a run was trained with: its file's dataclass with the run's recorded values."""
    base = load_baseline_config(Path(run["baseline_file"]))
    return replace(base, **{k: tuple(v) if isinstance(v, list) else v for k, v in run["config"].items()})


def score(job: tuple) -> tuple[str, float, int, dict]:
    """One held-out episode: job = (run.json, run directory, checkpoint entry, level, seed) ->
    (checkpoint sha256, level, seed, outcome or {"error": one line})."""
    import torch

    from hexbench.agents.policy import PolicyController, load_policy
    from hexbench.artifacts.manifest import CheckpointError
    from hexbench.suite.rollout import LocalActor, play

    torch.set_num_threads(1)
    run, run_dir, ckpt, level, seed = job
    config = run_config(run)
    try:
        policy = load_policy(config, Path(run_dir) / ckpt["file"], ckpt["sha256"])
    except CheckpointError as e:
        return ckpt["sha256"], level, seed, {"error": str(e)}
    task = task_between(load_suite(), run["terrain"], level)
    actor = LocalActor(PolicyController(config.action_mode, policy))
    row = play(task, seed, actor, where="policy", residual_scale=config.residual_scale).row
    return ckpt["sha256"], level, seed, {"success": row["success"], "progress_m": round(float(row["progress_m"]), 4),
                                         "end_reason": row["end_reason"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("candidates", nargs="+", help="RUN_DIR:ENV_STEPS")
    ap.add_argument("--levels", nargs="+", type=float, required=True)
    ap.add_argument("--episodes", type=int, default=20, help="held-out episodes per level")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, help="also write the outcomes here")
    args = ap.parse_args()
    candidates = [parse_candidate(c) for c in args.candidates]
    terrains = {run["terrain"] for run, _, _ in candidates}
    if len(terrains) != 1:
        raise SystemExit(f"error: candidates come from different terrains: {', '.join(sorted(terrains))}")
    terrain = terrains.pop()
    try:
        for level in args.levels:
            task_between(load_suite(), terrain, level)
        for run, _, _ in candidates:
            run_config(run)
    except (ValueError, TrainError) as e:
        raise SystemExit(f"error: {e}") from None
    jobs = [(run, str(d), c, lv, seed) for run, d, c in candidates for lv in args.levels
            for seed in heldout_seeds(terrain, lv, args.episodes)]
    with get_context("spawn").Pool(args.workers) as pool:
        outcomes = list(pool.imap_unordered(score, jobs))
    names = {c["sha256"]: f"{d}:{c['env_steps']}" for _, d, c in candidates}
    wins: dict[str, dict[float, int]] = defaultdict(lambda: defaultdict(int))
    ends: dict[str, Counter] = defaultdict(Counter)
    progress_m: dict[str, list[float]] = defaultdict(list)
    for sha, level, _seed, out in outcomes:
        if "error" in out:
            raise SystemExit(f"error: {out['error']}")
        wins[sha][level] += out["success"]
        ends[sha][out["end_reason"]] += 1
        progress_m[sha].append(out["progress_m"])
    for sha, name in names.items():
        per_level = "  ".join(f"{lv:g}: {wins[sha][lv]}/{args.episodes}" for lv in args.levels)
        total = sum(wins[sha].values())
        print(f"{name:50s} {per_level}   total {total}/{args.episodes * len(args.levels)}   "
              f"progress mean {np.mean(progress_m[sha]):.2f} m, max {max(progress_m[sha]):.2f} m   {dict(ends[sha])}")
    if args.json:
        args.json.write_text(json.dumps([{"checkpoint": names[sha], "level": lv, "seed": seed, **out}
                                         for sha, lv, seed, out in outcomes], indent=1))


if __name__ == "__main__":
    main()
