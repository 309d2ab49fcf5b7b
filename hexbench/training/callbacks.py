"""What a run reports while it trains (the SB3 callback `TrainingMonitor`): per-env episode returns
and successes over the last METRICS_WINDOW_EPISODES episodes, the progress bar, a progress.csv row
per env every `csv_every_s` and a checkpoint every `checkpoint_every_s` [s of wall time], or every
`checkpoint_every_steps` [env steps] where that is set: wall-time checkpoints fall at other env steps on
a faster or busier machine, so a re-run selects among other candidates; env-step checkpoints do not.
"""

from __future__ import annotations

import csv
import math
import time
from collections import deque

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from hexbench.training.runs import CSV_COLUMNS, PROGRESS_FILE
from hexbench.training.settings import TrainSettings

METRICS_WINDOW_EPISODES = 20


class TrainingMonitor(BaseCallback):
    """Per-env episode stats, the progress bar, the CSV and periodic checkpoints."""

    def __init__(self, settings: TrainSettings, run: dict, save_checkpoint, progress=None, task=None, console=None):
        super().__init__()
        self.settings, self.save_checkpoint = settings, save_checkpoint
        self.progress, self.task, self.console = progress, task, console
        n = settings.workers
        self.returns = [deque(maxlen=METRICS_WINDOW_EPISODES) for _ in range(n)]
        self.successes = [deque(maxlen=METRICS_WINDOW_EPISODES) for _ in range(n)]
        self.episodes = [0] * n
        self.wall_offset_s = float(run.get("wall_time_s", 0.0))
        self.t0 = time.monotonic()
        self.last_csv = self.t0
        self.last_ckpt = self.t0
        self.next_ckpt_steps = None  # with checkpoint_every_steps: the env-step count of the next checkpoint
        self.start_steps = None
        self.last_csv_steps = None  # env steps of the last progress.csv rows
        self.reward_sum = 0.0  # summed step rewards of this invocation, all envs
        self.reward_steps = 0

    def wall_time_s(self) -> float:
        return self.wall_offset_s + time.monotonic() - self.t0

    def _on_training_start(self) -> None:
        self.start_steps = self.num_timesteps
        self.t0 = time.monotonic()
        self.last_csv = self.last_ckpt = self.t0
        self._schedule_step_checkpoint()

    def _schedule_step_checkpoint(self) -> None:
        every = self.settings.checkpoint_every_steps
        if every:
            self.next_ckpt_steps = (self.num_timesteps // every + 1) * every

    def _checkpoint_due(self, now: float) -> bool:
        if self.settings.checkpoint_every_steps:
            return self.num_timesteps >= self.next_ckpt_steps
        return now - self.last_ckpt >= self.settings.checkpoint_every_s

    def _on_step(self) -> bool:
        # SB3 counts one step per decision; with actions held (DecisionInterval) a decision spends
        # several control steps, and the budget, checkpoints and progress.csv count control steps
        held = sum(int(info.get("decision_env_steps", 1)) - 1 for info in self.locals["infos"])
        if held:
            self.model.num_timesteps += held
            self.num_timesteps = self.model.num_timesteps
        # raw Table 1 rewards, also when the learner sees normalised ones
        env = self.training_env
        rewards = env.get_original_reward() if hasattr(env, "get_original_reward") else self.locals["rewards"]
        self.reward_sum += float(np.sum(rewards))
        self.reward_steps += len(rewards)
        for i, info in enumerate(self.locals["infos"]):
            ep = info.get("episode")
            if ep is not None:
                self.episodes[i] += 1
                self.returns[i].append(float(ep["r"]))
                self.successes[i].append(bool(info.get("is_success", False)))
        now = time.monotonic()
        if self.progress is not None and self.n_calls % 20 == 0:
            self._update_progress(now)
        if self._checkpoint_due(now):
            self.checkpoint()
        elif now - self.last_csv >= self.settings.csv_every_s:
            self.write_csv()
        return True

    def _update_progress(self, now: float) -> None:
        rate = (self.num_timesteps - self.start_steps) / max(now - self.t0, 1e-9)
        s = self.summary()
        sr = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.0f}%"
        rw = "-" if s["mean_episode_reward"] is None else f"{s['mean_episode_reward']:.0f}"
        self.progress.update(self.task, completed=self.num_timesteps,
                             info=f"{rate:.0f} steps/s  level {s['curriculum_level_mean']:g}  success {sr}  reward {rw}  "
                                  f"episodes {sum(self.episodes)}")

    def curriculum(self) -> list[dict]:
        return self.training_env.env_method("curriculum_state")

    def summary(self, curriculum: list[dict] | None = None) -> dict:
        all_r = [r for q in self.returns for r in q]
        all_s = [s for q in self.successes for s in q]
        levels = [c["level"] for c in curriculum] if curriculum else [
            float(info.get("level", math.nan)) for info in self.locals.get("infos", [])] or [math.nan]
        return {
            "mean_episode_reward": float(np.mean(all_r)) if all_r else None,
            "success_rate": float(np.mean(all_s)) if all_s else None,
            "episodes": int(sum(self.episodes)),
            "mean_step_reward": self.reward_sum / self.reward_steps if self.reward_steps else None,
            "curriculum_level_mean": float(np.mean(levels)),
            "curriculum_level_max": float(np.max(levels)),
        }

    def write_csv(self, curriculum: list[dict] | None = None) -> None:
        """One progress.csv row per env at the current env-step count (none if already written)."""
        if self.num_timesteps == self.last_csv_steps:
            return  # a checkpoint right after a CSV row: no duplicate rows
        self.last_csv_steps = self.num_timesteps
        curriculum = curriculum or self.curriculum()
        path = self.settings.run_dir / PROGRESS_FILE
        new = not path.exists()
        wall = self.wall_time_s()
        with open(path, "a", newline="") as f:
            w = csv.writer(f)
            if new:
                w.writerow(CSV_COLUMNS)
            for i, cur in enumerate(curriculum):
                r = np.mean(self.returns[i]) if self.returns[i] else math.nan
                s = np.mean(self.successes[i]) if self.successes[i] else math.nan
                w.writerow([self.num_timesteps, f"{wall:.1f}", i, self.episodes[i],
                            "" if math.isnan(r) else f"{r:.3f}", "" if math.isnan(s) else f"{s:.3f}",
                            f"{cur['level']:g}", cur["successes"]])
        self.last_csv = time.monotonic()
        if self.console is not None:
            s = self.summary(curriculum)
            self.console.log(f"{self.num_timesteps} env steps, {wall:.0f} s: reward {s['mean_episode_reward']}, "
                             f"success {s['success_rate']}, level {[c['level'] for c in curriculum]}")

    def checkpoint(self) -> None:
        """The CSV rows and a checkpoint, now."""
        curriculum = self.curriculum()
        self.write_csv(curriculum)
        self.save_checkpoint(self.model, self.num_timesteps, self.wall_time_s(), curriculum, self.summary(curriculum))
        self.last_ckpt = time.monotonic()
        self._schedule_step_checkpoint()

