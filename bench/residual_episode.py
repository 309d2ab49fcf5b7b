"""One episode of the CPG plus a given residual a_r: the loop the residual probes in bench/ share.

crest_residual.py, exploration_noise.py, residual_steering.py and stall_trace.py each play the
env in `cpg_residual` mode with a hand-made (or random) a_r instead of a policy; this module plays
such an episode and reports how it ended. Run them as `python bench/NAME.py`, which puts bench/
on the import path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hexbench.env import EnvConfig, HexapodEnv
from hexbench.robot import JOINT_NAMES

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


def play_residual(config: EnvConfig, residual: Residual, seed: int, *, max_steps: int | None = None,
                  on_step: StepHook | None = None) -> EpisodeEnd:
    """Play one episode (env seed `seed`) with a_t = a_c + eps * residual(obs, step)."""
    env = HexapodEnv(config)
    try:
        obs, _ = env.reset(seed=seed)
        yaw0_rad = float(env.robot_state.base_rpy_rad[2])
        limit = config.max_steps if max_steps is None else max_steps
        steps, done, info = 0, False, {"progress_m": 0.0, "lateral_m": 0.0}
        while not done and steps < limit:
            action = np.clip(residual(obs, steps), -1.0, 1.0).astype(np.float32)
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
            if on_step is not None:
                on_step(env, steps, done)
        yaw_rad = float(env.robot_state.base_rpy_rad[2])
        return EpisodeEnd(end_reason=str(info["end_reason"]) if done else "running",
                          progress_m=float(info["progress_m"]), lateral_m=float(info["lateral_m"]),
                          steps=steps, yaw_turned_deg=math.degrees(yaw_rad - yaw0_rad))
    finally:
        env.close()
