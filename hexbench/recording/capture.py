"""What the recorder keeps while an episode runs: references to per-step arrays, nothing encoded.

Per step it costs a few list appends plus the foot-contact query; everything else (quantising,
serialising, compressing) happens once in `on_end`, vectorised over the whole episode.
Row 0 of the state arrays is the state right after reset (time 0); step k (k >= 1) is the
state after the k-th control step, at simulated time k * control_dt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexbench.robot import FOOT_LINK_NAMES, JOINT_NAMES


@dataclass(frozen=True)
class EpisodeArrays:
    """One episode, stacked. n = number of control steps; state arrays have n + 1 rows."""

    control_dt_s: float
    time_ns: np.ndarray  # (n + 1,) int64, simulated time of each state row [ns]
    joint_pos_rad: np.ndarray  # (n + 1, 18)
    joint_vel_rad_per_s: np.ndarray  # (n + 1, 18)
    joint_torque_nm: np.ndarray  # (n + 1, 18)
    base_pos_m: np.ndarray  # (n + 1, 3)
    base_quat_xyzw: np.ndarray  # (n + 1, 4)
    reward: np.ndarray  # (n,)
    reward_term_names: tuple[str, ...]
    reward_terms: np.ndarray  # (n, len(names))
    action: np.ndarray  # (n, action_dim): what the controller returned (after validation)
    a_c: np.ndarray  # (n, 18) CPG joint angles [rad]
    a_r: np.ndarray  # (n, 18) policy part [rad]
    a_t: np.ndarray  # (n, 18) joint targets sent [rad]
    phases_rad: np.ndarray  # (n, 6) oscillator phases
    foot_contacts: np.ndarray  # (n, 6) bool
    progress_m: np.ndarray  # (n,)
    lateral_m: np.ndarray  # (n,)
    end_reason: str | None

    @property
    def num_steps(self) -> int:
        return len(self.reward)


def sim_time_ns(steps: np.ndarray | int, control_dt_s: float) -> np.ndarray:
    """Simulated time of control step k [ns], exact integer arithmetic on the rounded period."""
    return np.asarray(steps, dtype=np.int64) * np.int64(round(control_dt_s * 1e9))


class EpisodeCapture:
    """Collects an episode from the environment (see module docstring)."""

    def __init__(self) -> None:
        self._state: list = []
        self._steps: list[tuple] = []
        self._term_names: tuple[str, ...] | None = None
        self._end_reason: str | None = None
        self.control_dt_s = 1.0 / 60.0

    def reset(self, env) -> None:
        self.control_dt_s = env.config.physics.control_dt_s
        self._state = [env.robot_state]
        self._steps = []
        self._end_reason = None

    def step(self, env, action, reward, info) -> None:
        terms = info["reward_terms"]
        if self._term_names is None:
            self._term_names = tuple(terms)
        self._state.append(env.robot_state)
        self._steps.append((
            float(reward), tuple(terms.values()), np.array(action, dtype=np.float64), info["a_c"], info["a_r"],
            np.array(info["a_t"], dtype=np.float64), env.cpg.phases_rad, env.sim.foot_contacts(),
            info["progress_m"], info["lateral_m"],
        ))
        self._end_reason = info.get("end_reason")

    def arrays(self) -> EpisodeArrays:
        states = self._state
        cols = list(zip(*self._steps)) if self._steps else [()] * 10
        n = len(self._steps)

        def stack(seq, width, dtype=np.float64):
            return np.array(seq, dtype=dtype).reshape(n, width) if n else np.zeros((0, width), dtype)

        action_dim = len(cols[2][0]) if n else 18
        return EpisodeArrays(
            control_dt_s=self.control_dt_s,
            time_ns=sim_time_ns(np.arange(n + 1), self.control_dt_s),
            joint_pos_rad=np.array([s.joint_pos_rad for s in states]),
            joint_vel_rad_per_s=np.array([s.joint_vel_rad_per_s for s in states]),
            joint_torque_nm=np.array([s.joint_torque_nm for s in states]),
            base_pos_m=np.array([s.base_pos_m for s in states]),
            base_quat_xyzw=np.array([s.base_quat_xyzw for s in states]),
            reward=np.array(cols[0], dtype=np.float64).reshape(n),
            reward_term_names=self._term_names or (),
            reward_terms=stack(cols[1], len(self._term_names or ())),
            action=stack(cols[2], action_dim),
            a_c=stack(cols[3], len(JOINT_NAMES)),
            a_r=stack(cols[4], len(JOINT_NAMES)),
            a_t=stack(cols[5], len(JOINT_NAMES)),
            phases_rad=stack(cols[6], 6),
            foot_contacts=stack(cols[7], len(FOOT_LINK_NAMES), dtype=bool),
            progress_m=np.array(cols[8], dtype=np.float64).reshape(n),
            lateral_m=np.array(cols[9], dtype=np.float64).reshape(n),
            end_reason=self._end_reason,
        )
