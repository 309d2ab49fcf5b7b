"""The one episode loop: evaluation, verification by replay, checkpoint selection, Minari export and
the benchmarks all play episodes through `play`, so every check applies everywhere.

An actor is whatever produces actions: a sandboxed controller (hexbench.evaluation.sandbox.RemoteController),
an in-process one, a trusted policy of our own (`LocalActor`), or an action log (`LoggedActions`,
which replays an episode without its controller). The loop owns the environment, the episode
rules (through the env's judge), the metrics of the episode row and the action log: the actor
only sees observations (and camera images) and returns actions, which `check_action` validates
and casts to float32 before the simulator sees them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hexbench.errors import HexbenchError
from hexbench.suite.controller import CAMERA_GROUND_RGB, check_action
from hexbench.world.env import HexapodEnv

_add_reduce = np.add.reduce


class ReplayMismatch(HexbenchError):
    """An action log does not replay into the episode it claims (too short or too long)."""


@dataclass
class Episode:
    row: dict
    actions: np.ndarray  # (steps, action dim) float32: exactly what the simulator applied


class LocalActor:
    """A trusted in-process controller of our own (checkpoint selection, benchmarks): act(obs) only."""

    def __init__(self, ctrl, where: str = "policy"):
        self.ctrl, self.where = ctrl, where
        self.action_mode = ctrl.action_mode
        self.camera = None

    def reset(self, seed: int) -> None:
        self.ctrl.reset(seed)

    def act(self, obs: np.ndarray, step: int):
        return self.ctrl.act(obs)


class LoggedActions:
    """Replays an action log (hexbench.artifacts.action_log.ActionLog): the episode without its controller."""

    camera = None

    def __init__(self, log, where: str):
        self.log, self.where = log, where
        self.action_mode = log.action_mode

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: np.ndarray, step: int):
        if step >= self.log.steps:
            raise ReplayMismatch(f"{self.where}: the action log ends after {self.log.steps} steps but the replayed "
                                 f"episode goes on")
        return self.log.actions[step]


def make_env(task, action_mode: str, max_steps: int | None = None, **env_overrides) -> HexapodEnv:
    cfg = task.env_config(action_mode, **env_overrides)
    if max_steps is not None:
        cfg = replace(cfg, max_steps=max_steps)
    return HexapodEnv(cfg)


def play(task, seed: int, actor, *, index: int = 0, controller_seed: int | None = None, recorder=None,
         max_steps: int | None = None, where: str = "controller", env=None, **env_overrides) -> Episode:
    """Play one episode of `task` from episode seed `seed` with `actor`; return its row and actions.

    `env` plays in a prebuilt environment of the task instead of a fresh one; the caller closes it.
    `controller_seed` is what the actor's reset() receives (the evaluator passes a seed derived from
    the episode seed and a per-run secret, never the episode seed itself). `recorder` gets
    on_reset / on_step / on_end (hexbench.recording). A ControllerError or ReplayMismatch ends the
    episode and propagates; the env is closed either way (unless it was passed in).
    """
    own_env = env is None
    env = env or make_env(task, actor.action_mode, max_steps, **env_overrides)
    cfg = env.config
    terrain, level = task.terrain, task.level
    try:
        obs, _ = env.reset(seed=seed)
        if recorder is not None:
            recorder.on_reset(env)
        actor.reset(seed if controller_seed is None else controller_seed)
        see = _camera_channel(actor, env)
        dim = env.action_space.shape[0]
        dt = cfg.physics.control_dt_s
        limit = cfg.max_steps
        actions = np.empty((limit, dim), dtype=np.float32)
        rolls, pitches = [], []
        energy_j = 0.0
        max_abs_y = 0.0
        step = 0
        while True:
            if see is not None and step % actor.camera_every_steps == 0:
                see(step)
            action = check_action(actor.act(obs, step), dim, f"{where}: step {step}")
            actions[step] = action
            obs, reward, terminated, truncated, info = env.step(action)
            step += 1
            values = env.robot_state.values  # RobotState's vector: [18:36] joint velocities, [36:54] torques, [61:64] rpy
            rolls.append(values[61])
            pitches.append(values[62])
            energy_j += float(_add_reduce(abs(values[36:54] * values[18:36]))) * dt
            max_abs_y = max(max_abs_y, abs(info["lateral_m"]))
            if recorder is not None:
                recorder.on_step(env, obs, action, reward, info)
            if terminated or truncated:
                break
        if isinstance(actor, LoggedActions) and actor.log.steps != step:
            raise ReplayMismatch(f"{where}: the action log holds {actor.log.steps} steps but the replayed episode "
                                 f"ended after {step}")
        row = _row(terrain, level, index, seed, info, step, dt, rolls, pitches, energy_j, max_abs_y,
                   cfg.robot.total_mass_kg * cfg.physics.gravity_m_per_s2)
        return Episode(row, actions[:step].copy())
    finally:
        if own_env:
            env.close()


def _row(terrain, level, index, seed, info, steps, dt, rolls, pitches, energy_j, max_abs_y, weight_n) -> dict:
    reason = info["end_reason"]
    progress = info["progress_m"]
    sim_time = steps * dt
    return {
        "terrain": terrain, "level": level, "index": index, "seed": seed,
        "success": reason == "success", "end_reason": reason, "steps": steps, "sim_time_s": sim_time,
        "progress_m": progress, "time_to_goal_s": sim_time if reason == "success" else None,
        "mean_forward_speed_m_per_s": progress / sim_time if sim_time > 0 else None,
        "max_abs_y_m": max_abs_y,
        "roll_rms_deg": math.degrees(float(np.sqrt(np.mean(np.square(rolls))))),
        "pitch_rms_deg": math.degrees(float(np.sqrt(np.mean(np.square(pitches))))),
        "cost_of_transport": energy_j / (weight_n * progress) if progress > 0.05 else None,
    }


def _camera_channel(actor, env: HexapodEnv):
    """For an actor with a camera (a SeeingController): step -> render and send the image."""
    camera = getattr(actor, "camera", None)
    if camera is None:
        return None
    from hexbench.perception.views import paint_terrain
    from hexbench.world.camera import robot_camera_image

    paint_terrain(env.sim, CAMERA_GROUND_RGB)

    def see(step: int) -> None:
        actor.see(robot_camera_image(env.sim, camera), step)

    return see


__all__ = ["Episode", "LocalActor", "LoggedActions", "ReplayMismatch", "make_env", "play"]
