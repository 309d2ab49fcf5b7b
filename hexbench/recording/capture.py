"""What the recorder keeps while an episode runs: references to per-step arrays, nothing encoded.

The recordings log the episode at reduced rates (see mcap_episode.McapPrecision and
rerun_episode.RerunSettings), all multiples of one sampling period: every `every_n_steps`-th
control step and the step that ends the episode are *sampled*. On a sampled step the capture
keeps references to what the env made fresh (state, info with a_c, a_r, a_t), a copy of the
action, the oscillator state and the foot contacts (one PyBullet query, the costly part); on
every other step it keeps only the reward (the logged return sums every step). Everything else
(quantising, serialising, compressing) happens once in `on_end`, vectorised over the episode.

State row 0 is the state right after reset (time 0); state row i >= 1 is the state after
sampled step `steps[i - 1]`, at simulated time steps[i - 1] * control_dt.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import itemgetter

import numpy as np

from hexbench.world.robot import FOOT_LINK_NAMES, JOINT_NAMES


@dataclass(frozen=True)
class EpisodeArrays:
    """One episode, stacked. n = number of control steps, m = number of sampled steps."""

    control_dt_s: float
    every_n_steps: int  # the sampling period [control steps]: every n-th step and the last one are sampled
    steps: np.ndarray  # (m,) int64, the sampled steps (1-based, ascending, the last step included)
    time_ns: np.ndarray  # (m + 1,) int64, simulated time of each state row [ns]: reset, then the sampled steps
    joint_pos_rad: np.ndarray  # (m + 1, 18)
    joint_vel_rad_per_s: np.ndarray  # (m + 1, 18)
    joint_torque_nm: np.ndarray  # (m + 1, 18)
    base_pos_m: np.ndarray  # (m + 1, 3)
    base_quat_xyzw: np.ndarray  # (m + 1, 4)
    reward: np.ndarray  # (n,) EVERY step's reward
    reward_term_names: tuple[str, ...]
    reward_terms: np.ndarray  # (m, len(names)), at the sampled steps (as all arrays below)
    action: np.ndarray  # (m, action_dim): what the controller returned (after validation)
    a_c: np.ndarray  # (m, 18) CPG joint angles [rad]
    a_r: np.ndarray  # (m, 18) policy part [rad]
    a_t: np.ndarray  # (m, 18) joint targets sent [rad]
    phases_rad: np.ndarray  # (m, 6) oscillator phases
    foot_contacts: np.ndarray  # (m, 6) bool
    progress_m: np.ndarray  # (m,)
    lateral_m: np.ndarray  # (m,)
    end_reason: str | None

    @property
    def num_steps(self) -> int:
        return len(self.reward)

    @property
    def state_steps(self) -> np.ndarray:
        """(m + 1,) the control step of each state row (0 for the reset state)."""
        return np.concatenate([[0], self.steps]).astype(np.int64)

    def state_rows(self, every_n_steps: int) -> np.ndarray:
        """Indices of the state rows at a coarser rate: reset, every `every_n_steps`-th step, the last row.

        The rate must be a multiple of the sampling period (else those steps were not kept)."""
        if every_n_steps % self.every_n_steps:
            raise ValueError(f"a rate of every {every_n_steps} steps needs steps the capture did not keep "
                             f"(it sampled every {self.every_n_steps})")
        s = self.state_steps
        keep = s % every_n_steps == 0
        keep[-1] = True
        return np.flatnonzero(keep)


def touching_links(sim) -> frozenset:
    """Link indices of the robot that touch anything now (one contact query for the whole robot).

    Inside a running episode this is ~2.5x cheaper than `Simulation.foot_contacts()` (one query
    per foot; measured 19 vs 48 us per step), and the contact query is most of what recording
    costs per step.
    """
    import pybullet as p

    return frozenset(c[3] for c in p.getContactPoints(bodyA=sim.robot_id, physicsClientId=sim.client))


def foot_contacts(sim) -> np.ndarray:
    """Which feet touch anything: (6,) bool, the same answer as `Simulation.foot_contacts()` (tested)."""
    touching = touching_links(sim)
    return np.array([link in touching for link in sim.foot_link_indices])


def sim_time_ns(steps: np.ndarray | int, control_dt_s: float) -> np.ndarray:
    """Simulated time of control step k [ns], exact integer arithmetic on the rounded period."""
    return np.asarray(steps, dtype=np.int64) * np.int64(round(control_dt_s * 1e9))


class EpisodeCapture:
    """Collects an episode from the environment (see module docstring)."""

    def __init__(self, every_n_steps: int = 1) -> None:
        self.every_n_steps = max(1, int(every_n_steps))
        self.control_dt_s = 1.0 / 60.0
        self._reset_state = None
        self._rewards: list[float] = []
        self._rows: list[tuple] = []
        self._foot_links: tuple[int, ...] = ()

    def reset(self, env) -> None:
        self.control_dt_s = env.config.physics.control_dt_s
        self._foot_links = tuple(env.sim.foot_link_indices)
        self._reset_state = env.robot_state
        self._rewards = []
        self._rows = []

    def step(self, env, action, reward, info) -> None:
        rewards = self._rewards
        rewards.append(float(reward))
        k = len(rewards)
        if k % self.every_n_steps == 0 or info.get("end_reason") is not None:
            # references to what the env made fresh this step, a copy of the caller's action, the contacts
            self._rows.append((k, env.robot_state, info, np.array(action, dtype=np.float64), env.cpg.z,
                               touching_links(env.sim)))

    def arrays(self) -> EpisodeArrays:
        rows = self._rows
        m = len(rows)
        states = [self._reset_state] + [r[1] for r in rows]
        infos = [r[2] for r in rows]
        term_names = tuple(infos[0]["reward_terms"]) if m else ()
        feet = self._foot_links

        # np.concatenate joins many small 1-D arrays in C, several times faster than np.array or np.stack
        def stack(values, width):
            if not m:
                return np.zeros((0, width))
            return np.concatenate(values).astype(np.float64, copy=False).reshape(m, width)

        # RobotState fields are views into one float64 vector per step (hexbench.world.sim.RobotState.values):
        # stack those vectors once and take each field's columns at the offset its view has
        values0 = getattr(states[0], "values", None)
        packed = (np.concatenate([s.values for s in states]).reshape(len(states), -1)
                  if isinstance(values0, np.ndarray) and values0.ndim == 1 and values0.dtype == np.float64 else None)

        def state_field(name):
            f0 = getattr(states[0], name)
            if packed is not None and isinstance(f0, np.ndarray) and f0.base is values0 and f0.strides == (8,):
                start = (f0.__array_interface__["data"][0] - values0.__array_interface__["data"][0]) // 8
                return np.ascontiguousarray(packed[:, start:start + len(f0)])
            return np.array([getattr(s, name) for s in states])

        steps = np.array([r[0] for r in rows], dtype=np.int64)
        terms = itemgetter(*term_names) if term_names else None
        return EpisodeArrays(
            control_dt_s=self.control_dt_s,
            every_n_steps=self.every_n_steps,
            steps=steps,
            time_ns=sim_time_ns(np.concatenate([[0], steps]), self.control_dt_s),
            joint_pos_rad=state_field("joint_pos_rad"),
            joint_vel_rad_per_s=state_field("joint_vel_rad_per_s"),
            joint_torque_nm=state_field("joint_torque_nm"),
            base_pos_m=state_field("base_pos_m"),
            base_quat_xyzw=state_field("base_quat_xyzw"),
            reward=np.array(self._rewards, dtype=np.float64),
            reward_term_names=term_names,
            reward_terms=(np.array([terms(i["reward_terms"]) for i in infos], dtype=np.float64).reshape(m, -1)
                          if terms else np.zeros((m, 0))),
            action=stack([r[3] for r in rows], len(rows[0][3]) if m else 18),
            a_c=stack([i["a_c"] for i in infos], len(JOINT_NAMES)),
            a_r=stack([i["a_r"] for i in infos], len(JOINT_NAMES)),
            a_t=stack([i["a_t"] for i in infos], len(JOINT_NAMES)),
            phases_rad=np.angle(np.concatenate([r[4] for r in rows])).reshape(m, -1) if m else np.zeros((0, 6)),
            foot_contacts=np.array([[f in r[5] for f in feet] for r in rows],
                                   dtype=bool).reshape(m, len(FOOT_LINK_NAMES)),
            progress_m=np.array([i["progress_m"] for i in infos], dtype=np.float64).reshape(m),
            lateral_m=np.array([i["lateral_m"] for i in infos], dtype=np.float64).reshape(m),
            end_reason=infos[-1].get("end_reason") if m and rows[-1][0] == len(self._rewards) else None,
        )
