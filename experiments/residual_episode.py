"""One episode of the CPG plus a given residual a_r: the loop the residual experiments share.

crest_residual.py, exploration_noise.py, residual_steering.py and stall_trace.py each play the
env in `cpg_residual` mode with a hand-made (or random) a_r instead of a policy; this module plays
such an episode through the env's Gymnasium interface and reports how it ended. Run them as
`python experiments/NAME.py`, which puts experiments/ on the import path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

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


def play_residual(config: EnvConfig, residual: Residual, seed: int, *, max_steps: int | None = None,
                  on_step: StepHook | None = None) -> EpisodeEnd:
    """Play one episode (env seed `seed`) with a_t = a_c + eps * residual(obs, step) under the env's
    episode rules; stopping at `max_steps` first (below the config's step limit) ends as "running"."""
    if config.action_mode != "cpg_residual":
        raise ValueError(f"a residual needs action_mode 'cpg_residual', not {config.action_mode!r}")
    limit = config.max_steps if max_steps is None else min(max_steps, config.max_steps)
    stopped_early = limit < config.max_steps
    env = HexapodEnv(replace(config, max_steps=limit))
    try:
        obs, _ = env.reset(seed=seed)
        yaw0_rad = float(env.robot_state.base_rpy_rad[2])
        steps, info = 0, {"progress_m": 0.0, "lateral_m": 0.0, "end_reason": None}
        while True:
            action = np.clip(residual(obs, steps), -1.0, 1.0).astype(np.float32)
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            reason = info["end_reason"]
            done = terminated or truncated
            if on_step is not None:
                on_step(env, steps, done and not (reason == "step_limit" and stopped_early))
            if done:
                break
        yaw_rad = float(env.robot_state.base_rpy_rad[2])
    finally:
        env.close()
    running = info["end_reason"] == "step_limit" and stopped_early
    return EpisodeEnd(end_reason="running" if running else str(info["end_reason"]),
                      progress_m=float(info["progress_m"]), lateral_m=float(info["lateral_m"]),
                      steps=steps, yaw_turned_deg=math.degrees(yaw_rad - yaw0_rad))
