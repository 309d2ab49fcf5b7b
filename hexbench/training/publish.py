"""Shipping a run's checkpoint as baseline weights (`hexbench checkpoints publish`): the policy's
acting weights alone (no pickled data) in baselines/checkpoints/, with their entry in the one
checkpoint manifest (hexbench.artifacts.manifest).
"""

from __future__ import annotations

from pathlib import Path

from hexbench.artifacts.manifest import CheckpointError, write_entry
from hexbench.training.runs import best_checkpoint, checkpoint_at, read_run, utc_now
from hexbench.training.selection import SelectionError, heldout_best, selection_summary
from hexbench.training.settings import TrainError

PUBLISH_CHOICES: tuple[str, ...] = ("best", "heldout", "last")


def chosen_checkpoint(run_dir: Path, run: dict, which: str) -> dict:
    """The run's checkpoint entry that `which` names: best (training metrics), heldout (best of
    `hexbench checkpoints select`), last, or an env-step count."""
    if which == "best":
        return best_checkpoint(run)
    if which == "heldout":
        try:
            return heldout_best(run_dir, run)
        except SelectionError as e:
            raise TrainError(str(e)) from None
    if which == "last":
        return run["checkpoints"][-1]
    return checkpoint_at(run_dir, run, which, other_choices=PUBLISH_CHOICES)


def manifest_entry(run: dict, chosen: dict, which: str, file_name: str, sha256: str) -> dict:
    """The manifest entry of shipped weights taken from checkpoint `chosen` of `run`."""
    complete = run["env_steps"] >= run["total_steps"]  # the run reached its budget
    entry = {
        "file": file_name, "sha256": sha256, "method": run["method"], "terrain": run["terrain"],
        "algo": run["config"]["algo"], "action_mode": run["config"]["action_mode"], "seed": run["seed"],
        "command": run["sessions"][0]["command"] if run.get("sessions") else run.get("command", ""),
        "env_step_budget": run["total_steps"], "env_steps": chosen["env_steps"],
        "wall_time_s": chosen["wall_time_s"], "workers": run["workers"],
        "hexbench_commit": run["hexbench_commit"], "baseline_sha256": run["baseline_sha256"],
        "source_checkpoint_sha256": chosen["sha256"], "complete": complete,
        "status": (f"checkpoint at {chosen['env_steps']} env steps ({which}) of a complete run of {run['env_steps']} steps"
                   if complete else
                   f"PARTIAL run: checkpoint ({which}) at {chosen['env_steps']} of {run['total_steps']} env steps"),
        "metrics_at_checkpoint": {k: chosen.get(k) for k in ("mean_episode_reward", "success_rate", "episodes",
                                                             "curriculum_level_mean", "curriculum_level_max")},
        "published_utc": utc_now(),
    }
    source = run.get("init_from")
    if source:  # a warm-started run: count the source's training too, and say where it came from
        before = int(source.get("source_env_steps") or 0)
        entry["init_from"] = source
        entry["run_env_steps"] = chosen["env_steps"]
        entry["env_steps"] = before + chosen["env_steps"]
        entry["env_step_budget"] = before + run["total_steps"]
        entry["status"] += f"; warm-started from {source['manifest_key']} at {before} env steps ({entry['env_steps']} in all)"
    return entry


def publish_checkpoint(run_dir: Path, dest_dir: Path, which: str = "best") -> dict:
    """Copy a run's checkpoint (best, heldout, last, or a step count) as shipped policy-only weights.

    Writes <dest_dir>/<method>-<terrain>.zip (policy state_dict only, no pickled data) and its entry
    in <dest_dir>/manifest.json: sha256, command, env-step budget and steps reached, seed, wall
    time, hexbench commit, metrics at that checkpoint and whether the run was complete. A run
    warm-started with --init-from counts its source's env steps in env_steps and the budget, and
    keeps the source (file, sha256, command) under init_from.
    """
    from hexbench.agents.policy import acting_weights, load_policy_weights, save_policy_weights

    run_dir, dest_dir = Path(run_dir), Path(dest_dir)
    run = read_run(run_dir)
    if run is None:
        raise TrainError(f"{run_dir}: no run.json (not a training run directory)")
    if not run.get("checkpoints"):
        raise TrainError(f"{run_dir}: run has no checkpoints yet")
    chosen = chosen_checkpoint(run_dir, run, which)
    try:
        state = load_policy_weights(run_dir / chosen["file"], chosen["sha256"])
    except CheckpointError as e:
        raise TrainError(str(e)) from None
    dest_dir.mkdir(parents=True, exist_ok=True)
    key = f"{run['method']}-{run['terrain']}"
    sha = save_policy_weights(acting_weights(run["config"]["algo"], state), dest_dir / f"{key}.zip")
    entry = manifest_entry(run, chosen, which, f"{key}.zip", sha)
    selection = selection_summary(run_dir, chosen["sha256"])
    if selection is not None:  # how the shipped checkpoint did on held-out episodes, whoever chose it
        entry["selection"] = selection
    return write_entry(dest_dir, key, entry)
