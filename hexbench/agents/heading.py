"""Heading hold for controllers that act through the CPG (action modes `cpg_residual` and `cpg_params_steer`).

The open-loop tripod gait drifts: on the mixed course (6.3 m) most of the CPG's failures, and of a
hierarchy built on it, are lateral deviations (|y| > 0.8 m). `HeadingHold` steers back to the
course's centre line the way a hexapod turns: the stride of one side grows and of the other shrinks.
The CPG's hip angle is A1 y_i (hexbench.world.cpg, eq. 4); adding side_i u A1 y_i to it makes the
right legs' stride (1 + u) and the left legs' (1 - u) times the CPG's, so u > 0 turns left (yaw
grows). u is a proportional law on the heading error towards a point `lookahead_m` ahead on the
centre line (the line through the start and the target), limited to `max_turn`:

    u = clip(gain * wrap(atan2(target_y - y, lookahead_m) - yaw), -max_turn, max_turn)

It needs the CPG's output a_c at every step, which the observation does not carry: the steering
runs its own copy of the environment's CPG (same parameters, same integration, reset with the
episode), so its a_c is the environment's exactly. Only the hips are touched; knees and ankles
(the lift) stay as the CPG and the policy make them. Units: the returned residual is in action
units (divided by the environment's eps), ready to add to a policy's a_r.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from hexbench.world.cpg import LEG_SIDE, NUM_LEGS, CPGParams, HopfCPG
from hexbench.world.env import BASE_Y_INDEX, BASE_YAW_INDEX, STEER_MAX_TURN, TARGET_Y_INDEX

JOINTS_PER_LEG = 3


@dataclass(frozen=True)
class HeadingHold:
    gain: float = 1.0  # turn command u per radian of heading error
    max_turn: float = 0.3  # |u| limit: a side's stride changes by at most this fraction of the CPG's
    lookahead_m: float = 1.0  # aim at the centre line this far ahead [m]

    def __post_init__(self) -> None:
        if not (self.gain >= 0 and 0 <= self.max_turn < 1 and self.lookahead_m > 0):
            raise ValueError(f"HeadingHold needs gain >= 0, 0 <= max_turn < 1 and lookahead_m > 0; got {self}")

    def turn(self, obs: np.ndarray) -> float:
        """The turn command u for one observation (u > 0: turn left)."""
        y, yaw, target_y = float(obs[BASE_Y_INDEX]), float(obs[BASE_YAW_INDEX]), float(obs[TARGET_Y_INDEX])
        heading_error_rad = (math.atan2(target_y - y, self.lookahead_m) - yaw + math.pi) % (2 * math.pi) - math.pi
        return max(-self.max_turn, min(self.max_turn, self.gain * heading_error_rad))


class HeadingSteering:
    """The heading hold of one episode: `residual(obs)` once per control step, `reset()` per episode."""

    def __init__(self, hold: HeadingHold, cpg_params: CPGParams, control_dt_s: float, eps: float):
        if eps <= 0:
            raise ValueError(f"the environment's residual scale eps must be positive, got {eps}")
        self.hold, self.eps = hold, float(eps)
        self.cpg = HopfCPG(cpg_params, control_dt_s)
        self.reset()

    @classmethod
    def for_task(cls, hold: HeadingHold, task) -> HeadingSteering:
        """Steering matched to `task`'s environment in action mode cpg_residual (its CPG, control rate and eps)."""
        cfg = task.env_config("cpg_residual")
        return cls(hold, cfg.cpg, cfg.physics.control_dt_s, cfg.eps)

    def reset(self) -> None:
        self.cpg.reset()

    def residual(self, obs: np.ndarray) -> np.ndarray:
        """The hip residual for this step [action units], advancing the CPG copy by one step; call
        exactly once per control step, as the environment steps its CPG once per action."""
        a_c = self.cpg.step()
        u = self.hold.turn(obs)
        out = np.zeros(NUM_LEGS * JOINTS_PER_LEG)
        out[0::JOINTS_PER_LEG] = LEG_SIDE * (u / self.eps) * a_c[0::JOINTS_PER_LEG]
        return out


def turn_action_value(hold: HeadingHold, obs: np.ndarray, action_mode: str) -> float:
    """The turn value a[4] of a steering action mode (hexbench.world.env, u = STEER_MAX_TURN a[4])
    that makes the environment turn by the hold's u for this observation."""
    if action_mode not in STEER_MAX_TURN:
        raise ValueError(f"action mode {action_mode!r} has no turn; steering modes: {', '.join(STEER_MAX_TURN)}")
    return max(-1.0, min(1.0, hold.turn(obs) / STEER_MAX_TURN[action_mode]))


def with_held_heading(gait_action: np.ndarray, hold: HeadingHold, obs: np.ndarray, action_mode: str) -> np.ndarray:
    """A steering mode's action: the four gait values a policy chose and the hold's turn for `obs`."""
    return np.append(np.asarray(gait_action, dtype=np.float64)[:4], turn_action_value(hold, obs, action_mode))


class HeadingTurn(gym.Wrapper):
    """A steering-mode environment seen by a policy that chooses the gait alone: its action is the
    mode's four gait values, and the hold sets the turn from the latest observation at every control
    step (as PolicyController does in evaluation). Wrap the raw environment, below any observation
    scaling and below a DecisionInterval, so the turn follows every control step."""

    def __init__(self, env: gym.Env, hold: HeadingHold | None = None):
        super().__init__(env)
        self.action_mode = env.unwrapped.config.action_mode
        if self.action_mode not in STEER_MAX_TURN:
            raise ValueError(f"HeadingTurn needs a steering action mode ({', '.join(STEER_MAX_TURN)}); "
                             f"got {self.action_mode!r}")
        self.hold = hold or HeadingHold()
        space = env.action_space
        self.action_space = gym.spaces.Box(space.low[:4], space.high[:4], dtype=space.dtype)
        self._obs: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._obs = obs
        return obs, info

    def step(self, action):
        full = with_held_heading(action, self.hold, self._obs, self.action_mode)
        obs, reward, terminated, truncated, info = self.env.step(full)
        self._obs = obs
        return obs, reward, terminated, truncated, info
