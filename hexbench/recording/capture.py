"""What the recorder keeps while an episode runs: references to per-step arrays, nothing encoded.

Per step it costs a few list appends plus the foot-contact query; everything else (quantising,
serialising, compressing) happens once in `on_end`, vectorised over the whole episode.
Row 0 of the state arrays is the state right after reset (time 0); step k (k >= 1) is the
state after the k-th control step, at simulated time k * control_dt.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import itemgetter

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
    contact_steps: np.ndarray  # (c,) int64, the 1-based steps at which the foot contacts were queried
    foot_contacts: np.ndarray  # (c, 6) bool, at `contact_steps` (not every step: the query is the costly part)
    progress_m: np.ndarray  # (n,)
    lateral_m: np.ndarray  # (n,)
    end_reason: str | None

    @property
    def num_steps(self) -> int:
        return len(self.reward)


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


def sampled_steps(num_steps: int, every_n_steps: int) -> np.ndarray:
    """The 1-based steps logged at a reduced rate: every n-th step and always the last one."""
    every = max(1, int(every_n_steps))
    steps = np.arange(every, num_steps + 1, every, dtype=np.int64)
    if num_steps and (not len(steps) or steps[-1] != num_steps):
        steps = np.append(steps, np.int64(num_steps))
    return steps


class EpisodeCapture:
    """Collects an episode from the environment (see module docstring).

    It keeps references, not copies, of what the env returns (fresh arrays every step: the
    state, a_c, a_r, the sent targets); only the caller's action is copied. The foot contacts
    (a PyBullet query, most of the per-step cost) are queried only every `contacts_every_n_steps`
    steps and on the step that ends the episode (its info has an `end_reason`): the steps that
    the per-step metrics are logged at.
    """

    def __init__(self, contacts_every_n_steps: int = 1) -> None:
        self._state: list = []
        self._steps: list[tuple] = []
        self._contacts: list[tuple[int, frozenset]] = []
        self._foot_links: tuple[int, ...] = ()
        self._every = max(1, int(contacts_every_n_steps))
        self.control_dt_s = 1.0 / 60.0

    def reset(self, env) -> None:
        self.control_dt_s = env.config.physics.control_dt_s
        self._foot_links = tuple(env.sim.foot_link_indices)
        self._state = [env.robot_state]
        self._steps = []
        self._contacts = []

    def step(self, env, action, reward, info) -> None:
        # Only references to what the env made fresh this step, plus the contact query: the rest
        # (phases from the oscillator state z, contacts per foot, the info fields) is unpacked
        # once, vectorised, in arrays().
        self._state.append(env.robot_state)
        steps = self._steps
        steps.append((float(reward), info, np.array(action, dtype=np.float64), env.cpg.z))
        k = len(steps)
        if k % self._every == 0 or info.get("end_reason") is not None:
            self._contacts.append((k, touching_links(env.sim)))

    def arrays(self) -> EpisodeArrays:
        states = self._state
        steps = self._steps
        n = len(steps)
        infos = [st[1] for st in steps]
        term_names = tuple(infos[0]["reward_terms"]) if n else ()
        feet = self._foot_links

        # np.concatenate joins many small 1-D arrays in C, several times faster than np.array or np.stack
        def stack(values, width):
            return np.concatenate(values).astype(np.float64, copy=False).reshape(n, width) if n else np.zeros((0, width))

        # RobotState fields are views into one float64 vector per step (hexbench.sim.RobotState.values):
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

        terms = itemgetter(*term_names) if term_names else None
        return EpisodeArrays(
            control_dt_s=self.control_dt_s,
            time_ns=sim_time_ns(np.arange(n + 1), self.control_dt_s),
            joint_pos_rad=state_field("joint_pos_rad"),
            joint_vel_rad_per_s=state_field("joint_vel_rad_per_s"),
            joint_torque_nm=state_field("joint_torque_nm"),
            base_pos_m=state_field("base_pos_m"),
            base_quat_xyzw=state_field("base_quat_xyzw"),
            reward=np.array([st[0] for st in steps], dtype=np.float64).reshape(n),
            reward_term_names=term_names,
            reward_terms=(np.array([terms(i["reward_terms"]) for i in infos], dtype=np.float64).reshape(n, -1)
                          if terms else np.zeros((n, 0))),
            action=stack([st[2] for st in steps], len(steps[0][2]) if n else 18),
            a_c=stack([i["a_c"] for i in infos], len(JOINT_NAMES)),
            a_r=stack([i["a_r"] for i in infos], len(JOINT_NAMES)),
            a_t=stack([i["a_t"] for i in infos], len(JOINT_NAMES)),
            phases_rad=np.angle(np.concatenate([st[3] for st in steps])).reshape(n, -1) if n else np.zeros((0, 6)),
            progress_m=np.array([i["progress_m"] for i in infos], dtype=np.float64).reshape(n),
            lateral_m=np.array([i["lateral_m"] for i in infos], dtype=np.float64).reshape(n),
            end_reason=infos[-1].get("end_reason") if n else None,
            contact_steps=np.array([c[0] for c in self._contacts], dtype=np.int64),
            foot_contacts=np.array([[f in c[1] for f in feet] for c in self._contacts],
                                   dtype=bool).reshape(len(self._contacts), len(FOOT_LINK_NAMES)),
        )
