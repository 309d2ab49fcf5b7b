"""One episode of the CPG plus a given residual a_r: the loop the residual probes in bench/ share.

crest_residual.py, exploration_noise.py, residual_steering.py and stall_trace.py each play the
env in `cpg_residual` mode with a hand-made (or random) a_r instead of a policy; this module plays
such an episode and reports how it ended. Run them as `python bench/NAME.py`, which puts bench/
on the import path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from hexbench.suite.rollout import play
from hexbench.world.env import EnvConfig, HexapodEnv
from hexbench.world.robot import JOINT_NAMES

# (noisy observation, control step from 0) -> a_r, clipped to [-1, 1] before it is sent
Residual = Callable[[np.ndarray, int], np.ndarray]
# (env, control steps taken, episode over) after every step, e.g. to print a trace
StepHook = Callable[[HexapodEnv, int, bool], None]


def zero_residual(obs: np.ndarray, step: int) -> np.ndarray:
    """a_r = 0: the open-loop CPG."""
    return np.zeros(len(JOINT_NAMES))


@dataclass(frozen=True)
class EpisodeEnd:
    end_reason: str  # the env's end reason; "running" if stopped by max_steps first
    progress_m: float  # forward progress [m]
    lateral_m: float  # lateral offset [m]
    steps: int  # control steps played
    yaw_turned_deg: float  # base yaw at the end minus at reset [deg]


class _ResidualActor:
    action_mode = "cpg_residual"
    camera = None

    def __init__(self, residual: Residual):
        self.residual = residual

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: np.ndarray, step: int) -> np.ndarray:
        return np.clip(self.residual(obs, step), -1.0, 1.0).astype(np.float32)


class _StepHook:
    """The rollout's recorder interface, used to pass every step to `on_step` and keep the last info."""

    def __init__(self, on_step: StepHook | None, stopped_early: bool):
        self.callback, self.stopped_early = on_step, stopped_early
        self.steps, self.info = 0, {"progress_m": 0.0, "lateral_m": 0.0}

    def on_reset(self, env) -> None:
        self.yaw0_rad = float(env.robot_state.base_rpy_rad[2])

    def on_step(self, env, obs, action, reward, info) -> None:
        self.steps, self.info = self.steps + 1, info
        if self.callback is not None:
            reason = info["end_reason"]
            self.callback(env, self.steps, reason is not None and not (reason == "step_limit" and self.stopped_early))


def play_residual(config: EnvConfig, residual: Residual, seed: int, *, max_steps: int | None = None,
                  on_step: StepHook | None = None) -> EpisodeEnd:
    """Play one episode (env seed `seed`) with a_t = a_c + eps * residual(obs, step), through the one
    episode loop (hexbench.suite.rollout.play); stopping at `max_steps` first ends as "running"."""
    limit = config.max_steps if max_steps is None else min(max_steps, config.max_steps)
    stopped_early = limit < config.max_steps
    env = HexapodEnv(replace(config, max_steps=limit))
    hook = _StepHook(on_step, stopped_early)
    try:
        row = play(None, seed, _ResidualActor(residual), recorder=hook, env=env).row
        yaw_rad = float(env.robot_state.base_rpy_rad[2])
    finally:
        env.close()
    running = row["end_reason"] == "step_limit" and stopped_early
    return EpisodeEnd(end_reason="running" if running else str(row["end_reason"]),
                      progress_m=float(row["progress_m"]), lateral_m=float(hook.info["lateral_m"]),
                      steps=row["steps"], yaw_turned_deg=math.degrees(yaw_rad - hook.yaw0_rad))
