"""A training run's directory and its run.json: creating it, checking a resume against it, saving
checkpoints into it, and choosing checkpoints from it. Default directory
training/<method>-<terrain>-seed<S>/:

    run.json             what was run (command, config, seed, budget, commit) + every checkpoint
                         with its sha256, env steps, wall time and metrics; the curriculum state
    progress.csv         one row per env every `csv_every_s` (CSV_COLUMNS): env_steps, wall_time_s,
                         env_index, episodes, mean_episode_reward, success_rate (last 20 episodes of
                         that env), curriculum_level, curriculum_successes
    checkpoints/step_<N>.zip   full SB3 models (for resuming), every `checkpoint_every_s`
    train.log            (when started in the background with output redirected)

Running the same command again resumes from the last checkpoint (sha256 checked against run.json
first), with the curriculum level of every env restored; --steps is the total budget, not the
remainder. A run directory holding another run (method, terrain, seed, workers, config, options)
is refused.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path

from hexbench.artifacts.files import atomic_path, sha256_file, write_json_atomic
from hexbench.artifacts.provenance import git_commit
from hexbench.training.settings import TrainError, TrainSettings

RUN_FILE = "run.json"
PROGRESS_FILE = "progress.csv"
CSV_COLUMNS = ("env_steps", "wall_time_s", "env_index", "episodes", "mean_episode_reward", "success_rate",
               "curriculum_level", "curriculum_successes")


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def read_run(run_dir: Path) -> dict | None:
    """The run.json of a run directory (None if there is none)."""
    path = Path(run_dir) / RUN_FILE
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise TrainError(f"{path}: not valid JSON ({e.msg}); move the run directory away to start afresh") from None


def best_checkpoint(run: dict) -> dict:
    """The best checkpoint of a run: highest mean curriculum level, then success rate, then reward."""
    if not run.get("checkpoints"):
        raise TrainError("run has no checkpoints yet")

    def key(c):
        reward = c.get("mean_episode_reward")
        return (c.get("curriculum_level_mean") or 0.0, c.get("success_rate") or 0.0,
                reward if reward is not None else -math.inf, c["env_steps"])
    return max(run["checkpoints"], key=key)


def checkpoint_at(run_dir: Path, run: dict, env_steps: str, other_choices: tuple[str, ...] = ()) -> dict:
    """The run's checkpoint at `env_steps` (as typed); a one-line TrainError naming the valid choices if none."""
    for c in run["checkpoints"]:
        if str(c["env_steps"]) == env_steps:
            return c
    valid = ", ".join([*other_choices, *(str(c["env_steps"]) for c in run["checkpoints"])])
    raise TrainError(f"{run_dir}: no checkpoint {env_steps!r}; valid: {valid}")


def _recorded_options(settings: TrainSettings, cfg_dict: dict) -> tuple[tuple[str, object], ...]:
    """(run.json key, value now) of everything a resumed run must share with the run it continues."""
    return (("method", settings.method), ("terrain", settings.terrain), ("seed", settings.seed),
            ("workers", settings.workers), ("config", cfg_dict), ("fixed_level", settings.fixed_level),
            ("curriculum_levels", asdict(settings.curriculum) if settings.curriculum else None),
            ("value_warmup_steps", settings.value_warmup_steps or None),
            ("init_from", str(settings.init_from) if settings.init_from else None))


def check_resume(run_dir: Path, previous: dict, settings: TrainSettings, cfg_dict: dict) -> None:
    """TrainError unless the run recorded in `previous` is the one `settings` asks for."""
    # a config field added after the run started is absent from its run.json: it resumes only with
    # that field off (False / None), which is how the run was trained
    recorded = {**previous, "config": {**{k: v for k, v in cfg_dict.items() if not v}, **previous.get("config", {})},
                "init_from": (previous.get("init_from") or {}).get("file")}  # compared by source file
    for key, now in _recorded_options(settings, cfg_dict):
        was = recorded.get(key)
        if was != now:
            raise TrainError(f"{run_dir}: holds a run with {key}={was!r}, not {now!r}; "
                             f"choose another --out or move it away")


def new_run(settings: TrainSettings, cfg_dict: dict, init_from: dict | None) -> dict:
    """The run.json content of a run that has not trained yet."""
    return {
        "method": settings.method, "baseline_file": str(settings.baseline_path),
        "baseline_sha256": sha256_file(settings.baseline_path), "terrain": settings.terrain,
        "seed": settings.seed, "workers": settings.workers, "config": cfg_dict, "fixed_level": settings.fixed_level,
        "started_utc": utc_now(), "hexbench_commit": git_commit(),
        "wall_time_s": 0.0, "env_steps": 0, "checkpoints": [], "curriculum": None, "sessions": [],
        "init_from": init_from,
        "curriculum_levels": asdict(settings.curriculum) if settings.curriculum else None,
        "value_warmup_steps": settings.value_warmup_steps or None,
    }


def start_session(run_dir: Path, run: dict, settings: TrainSettings) -> dict:
    """Create the run directory, record this invocation as a session of the run and write run.json."""
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "checkpoints").mkdir(exist_ok=True)
    run["total_steps"] = settings.total_steps
    run["command"] = settings.command
    run["sessions"].append({"started_utc": utc_now(), "command": settings.command, "hexbench_commit": git_commit(),
                            "from_env_steps": run["env_steps"]})
    write_json_atomic(run_dir / RUN_FILE, run)
    return run


def nan_to_none(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def save_checkpoint(run_dir: Path, run: dict, model, env_steps: int, wall_time_s: float, curriculum: list[dict],
                    summary: dict, reward_normalizer: dict | None) -> None:
    """Save the full SB3 model as checkpoints/step_<N>.zip and list it, with its metrics, in run.json."""
    name = f"checkpoints/step_{env_steps:010d}.zip"
    path = run_dir / name
    with atomic_path(path) as tmp:
        model.save(tmp)
    entry = {"file": name, "sha256": sha256_file(path), "env_steps": int(env_steps),
             "wall_time_s": round(wall_time_s, 1), "saved_utc": utc_now(),
             **{k: nan_to_none(v) if isinstance(v, float) else v for k, v in summary.items()}}
    if reward_normalizer is not None:
        entry["reward_normalizer"] = reward_normalizer
    run["checkpoints"] = [c for c in run["checkpoints"] if c["file"] != name] + [entry]
    run["env_steps"] = int(env_steps)
    run["wall_time_s"] = round(wall_time_s, 1)
    run["curriculum"] = curriculum
    write_json_atomic(run_dir / RUN_FILE, run)
