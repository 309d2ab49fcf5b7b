"""The epsilon search of paper section 3.2 (`hexbench sweep epsilon --terrain T`).

The paper trains PPO-CPG at the terrain's hardest curriculum level for 10 trials of 100,000 steps
at each eps in {0, 0.1, ..., 1} and keeps the eps with the highest average reward (0.6 rough, 0.4
slopes, 0.3 stairs). Here each (eps, trial) is one ordinary training run (hexbench.train) with
`residual_scale=eps` at the level `CURRICULA[terrain].max_level`, no curriculum, seed = trial index;
the score of a trial is its mean reward per env step over the whole trial (well defined even when a
short trial finishes few 4000-step episodes); the mean episode reward of its last 20 episodes is
reported beside it. Trials are run directories under the sweep folder, so an interrupted sweep
resumes where it stopped. Defaults are short (the paper's budget is 11 x 10 x 100k = 11M steps).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.env import CURRICULA
from hexbench.train import TRAIN_TERRAINS, TrainError, TrainSettings, read_run, train

SWEEP_COLUMNS = ("eps", "trial", "seed", "level", "env_steps", "wall_time_s", "mean_step_reward",
                 "mean_episode_reward", "episodes", "success_rate")
PAPER_EPS: dict[str, float] = {"rough": 0.6, "slopes": 0.4, "stairs": 0.3}


@dataclass(frozen=True)
class EpsilonSweep:
    terrain: str
    baseline_path: Path = Path("baselines/ppo_cpg.py")
    eps_values: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(11))
    trials: int = 1
    steps_per_trial: int = 4096  # env steps
    out_dir: Path | None = None  # None -> training/sweep-epsilon-<terrain>
    overrides: tuple[tuple[str, object], ...] = ()

    @property
    def folder(self) -> Path:
        return Path(self.out_dir) if self.out_dir else Path("training") / f"sweep-epsilon-{self.terrain}"

    @property
    def level(self) -> float:
        return CURRICULA[self.terrain].max_level


def run_sweep(sweep: EpsilonSweep, command: str = "", progress_callback=None) -> list[dict]:
    """Train every (eps, trial); write <folder>/epsilon.csv; return its rows."""
    if sweep.terrain not in TRAIN_TERRAINS:
        raise TrainError(f"unknown terrain {sweep.terrain!r}; valid terrains: {', '.join(TRAIN_TERRAINS)}")
    bad = [e for e in sweep.eps_values if not 0.0 <= e <= 1.0]
    if bad:
        raise TrainError(f"eps values must lie in [0, 1]; got {bad}")
    if sweep.trials < 1 or sweep.steps_per_trial < 1:
        raise TrainError("--trials and --steps must be >= 1")
    rows = []
    for eps in sweep.eps_values:
        for trial in range(sweep.trials):
            run_dir = sweep.folder / f"eps{eps:.2f}-trial{trial}"
            settings = TrainSettings(
                baseline_path=sweep.baseline_path, terrain=sweep.terrain, total_steps=sweep.steps_per_trial,
                seed=trial, workers=1, out_dir=run_dir, overrides=sweep.overrides + (("residual_scale", float(eps)),),
                command=command, show_progress=False, fixed_level=sweep.level, checkpoint_every_s=1e9,
            )
            train(settings)
            run = read_run(run_dir)
            last = run["checkpoints"][-1]
            rows.append({"eps": eps, "trial": trial, "seed": trial, "level": sweep.level,
                         "env_steps": last["env_steps"], "wall_time_s": last["wall_time_s"],
                         "mean_step_reward": last.get("mean_step_reward"),
                         "mean_episode_reward": last.get("mean_episode_reward"),
                         "episodes": last.get("episodes"), "success_rate": last.get("success_rate")})
            if progress_callback:
                progress_callback(rows[-1])
    path = sweep.folder / "epsilon.csv"
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=SWEEP_COLUMNS)
        w.writeheader()
        w.writerows({k: ("" if v is None else v) for k, v in r.items()} for r in rows)
    tmp.replace(path)
    return rows


def best_eps(rows: list[dict]) -> tuple[float, dict[float, float]]:
    """(eps with the highest mean step reward over its trials, {eps: that mean})."""
    by_eps: dict[float, list[float]] = {}
    for r in rows:
        if r["mean_step_reward"] is not None:
            by_eps.setdefault(r["eps"], []).append(r["mean_step_reward"])
    means = {e: float(np.mean(v)) for e, v in by_eps.items()}
    if not means:
        return math.nan, means
    return max(means, key=means.get), means
