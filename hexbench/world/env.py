"""The hexbench Gymnasium environment: JetHexa on a terrain, one of three action modes.

Observation (62 float32, paper section 3.3), in this order:
  [0:18]  joint positions [rad]          [18:36] joint velocities [rad/s]
  [36:54] joint torques [N m]            [54:57] base x, y, z [m] (world)
  [57:60] base roll, pitch, yaw [rad]    [60:62] target x, y [m] (world)
plus optional Gaussian noise xi with the standard deviations of `ObservationNoise`.

Action modes (all Box(-1, 1) so every learner sees a normalised space):
  joint         pure DRL: a in [-1, 1]^18 maps linearly onto each joint's [lower, upper] limits;
  cpg_residual  a_t = a_c + eps a_r (eq. 6): a_r in [-1, 1]^18 [rad], a_c the CPG's joint angles,
                eps 0.6 rough / 0.4 slopes / 0.3 stairs by default (paper 3.2);
  cpg_params    HRL: a in [-1, 1]^4 maps linearly onto omega_swing in [pi/2, pi] rad/s,
                A1 in [-1, 1], A2 in [-0.5, 1], A3 in [-1, 0.5] (paper 4.3);
  cpg_params_wide  the same with A2 in [-0.5, 1.2] and A3 in [-1, 1]: not in the paper; its ranges
                exclude the paper's own CPG gait (A2 = 1.2, A3 = 1.0, section 2.2), these contain it;
  cpg_params_steer  cpg_params_wide plus a fifth value, a turn u = 0.3 a[4]: the right legs' hip
                stride is (1 + u) times the CPG's and the left legs' (1 - u) times (u > 0 turns
                left; the turn of hexbench.agents.heading). Not in the paper: a gait chosen from
                four symmetric parameters cannot steer against the drift that ends episodes at
                |y| > 0.8 m.

Episode end: the rules of hexbench.world.protocol (fall, |y| > 0.8 m, success at 2.5 m ahead, an
optional stall rule that the evaluation protocol turns on, all `terminated`; or the
4000-step limit, `truncated`. Control runs at 60 Hz (4 physics steps of 1/240 s).

Level: every episode plays at `EnvConfig.level`, or at the level given as reset option
(`env.reset(options={"level": 7.0})`).
The env takes its config as an `EnvConfig` or as keyword arguments of plain data (what Gymnasium
registrations carry): nested configs as dicts of their fields, `noise=None` for no observation noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import gymnasium as gym
import numpy as np

from hexbench.world.cpg import LEG_SIDE, CPGParams, HopfCPG
from hexbench.world.protocol import EpisodeJudge, EpisodeRules
from hexbench.world.rewards import TABLE1_WEIGHTS, difficulty_factor, reward_terms, total_reward
from hexbench.world.robot import NUM_JOINTS, JetHexaSpec
from hexbench.world.sim import PhysicsConfig, Simulation, clip_ufunc
from hexbench.world.terrain import TERRAIN_KINDS, make_terrain

ACTION_MODES: tuple[str, ...] = ("joint", "cpg_residual", "cpg_params", "cpg_params_wide", "cpg_params_steer")
# The mixed course takes the largest eps, so that a controller switching policies (HLTA) can send
# each policy's residual unclipped (see baselines/hlta.py).
DEFAULT_RESIDUAL_SCALE: dict[str, float] = {"rough": 0.6, "slopes": 0.4, "stairs": 0.3, "flat": 0.6, "mixed": 0.6}
# HRL parameter ranges (paper 4.3): omega_swing [rad/s], A1, A2, A3.
CPG_PARAM_LOW = np.array([math.pi / 2, -1.0, -0.5, -1.0])
CPG_PARAM_HIGH = np.array([math.pi, 1.0, 1.0, 0.5])
# The gait-parameter action modes and their ranges (low, high): cpg_params_wide reaches the paper's
# CPG gait (A2 1.2, A3 1.0), which the paper's HRL ranges clip to 1.0 and 0.5.
CPG_PARAM_RANGES: dict[str, tuple[np.ndarray, np.ndarray]] = {
    "cpg_params": (CPG_PARAM_LOW, CPG_PARAM_HIGH),
    "cpg_params_wide": (CPG_PARAM_LOW, np.array([math.pi, 1.0, 1.2, 1.0])),
}
CPG_PARAM_RANGES["cpg_params_steer"] = CPG_PARAM_RANGES["cpg_params_wide"]
# The gait-parameter modes with a fifth action value, the turn, and its largest magnitude (a side's
# hip stride changes by at most this fraction of the CPG's; as hexbench.agents.heading's default).
STEER_MAX_TURN: dict[str, float] = {"cpg_params_steer": 0.3}


def cpg_params_action(omega_swing: float, a1: float, a2: float, a3: float,
                      action_mode: str = "cpg_params", turn: float = 0.0) -> tuple[float, ...]:
    """The action in [-1, 1]^4 of a gait-parameter mode for a gait (omega_swing [rad/s], A1, A2, A3),
    each clipped to the mode's range; a steering mode appends the turn u (clipped to its largest)."""
    low, high = CPG_PARAM_RANGES[action_mode]
    params = np.clip(np.array([omega_swing, a1, a2, a3], dtype=np.float64), low, high)
    action = tuple(float(a) for a in (params - low) / (high - low) * 2.0 - 1.0)
    if action_mode in STEER_MAX_TURN:
        action += (float(np.clip(turn / STEER_MAX_TURN[action_mode], -1.0, 1.0)),)
    return action


def action_size(action_mode: str) -> int:
    """Length of an action of `action_mode`: 4 gait parameters (and a turn), else one value per joint."""
    if action_mode in CPG_PARAM_RANGES:
        return 5 if action_mode in STEER_MAX_TURN else 4
    return NUM_JOINTS


OBS_DIM = 62
# Where controllers read the base pose and the target in an observation (the layout above)
BASE_X_INDEX, BASE_Y_INDEX, BASE_YAW_INDEX, TARGET_X_INDEX, TARGET_Y_INDEX = 54, 55, 59, 60, 61
# Observation bounds (generous physical limits; observations are clipped to them).
OBS_HIGH = np.concatenate([
    np.full(18, 2 * math.pi), np.full(18, 100.0), np.full(18, 20.0), np.full(3, 100.0), np.full(3, 4.0),
    np.full(2, 100.0),
]).astype(np.float32)
_OBS_HIGH_64 = OBS_HIGH.astype(np.float64)
_OBS_LOW_64 = -_OBS_HIGH_64
# Where the observation's first 60 entries sit in RobotState.values (joints, base xyz, base rpy).
_OBS_FROM_STATE = np.r_[0:57, 61:64]
# Observation noise is drawn this many control steps at a time: Generator.standard_normal fills
# arrays element by element from one stream, so a (k, 62) draw holds the same numbers, in the
# same order, as k draws of 62 (tests/test_env.py checks this).
_NOISE_BLOCK_STEPS = 32
_add_reduce = np.add.reduce
END_REASONS: tuple[str, ...] = ("success", "lateral_deviation", "fall", "stalled", "step_limit")
MAX_EPISODE_STEPS = 4000  # control steps [1/60 s] of an episode unless a task says otherwise


@dataclass(frozen=True)
class ObservationNoise:
    """Standard deviations of the Gaussian observation noise xi (0 disables a group)."""

    joint_pos_rad: float = 0.01
    joint_vel_rad_per_s: float = 0.05
    joint_torque_nm: float = 0.05
    base_pos_m: float = 0.01
    base_rpy_rad: float = 0.01

    def std_vector(self) -> np.ndarray:
        return np.concatenate([
            np.full(18, self.joint_pos_rad), np.full(18, self.joint_vel_rad_per_s),
            np.full(18, self.joint_torque_nm), np.full(3, self.base_pos_m), np.full(3, self.base_rpy_rad),
            np.zeros(2),
        ])


NO_NOISE = ObservationNoise(0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class EnvConfig:
    terrain: str
    level: float = 0.0  # paper units: cm (rough, stairs), deg (slopes); a reset option may give another
    action_mode: str = "cpg_residual"
    residual_scale: float | None = None  # eps; None -> DEFAULT_RESIDUAL_SCALE[terrain]
    noise: ObservationNoise = field(default_factory=ObservationNoise)
    max_steps: int = MAX_EPISODE_STEPS
    goal_distance_m: float = 2.5
    max_lateral_deviation_m: float = 0.8
    fall_tilt_deg: float = 60.0
    stall_window_s: float | None = None  # None: no stall rule
    stall_min_progress_m: float = 0.05
    init_xy_jitter_m: float = 0.02  # uniform +- start position perturbation
    init_yaw_jitter_rad: float = 0.05  # uniform +- start heading perturbation
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    robot: JetHexaSpec = field(default_factory=JetHexaSpec)
    cpg: CPGParams = field(default_factory=CPGParams)

    def __post_init__(self) -> None:
        if self.terrain not in TERRAIN_KINDS:
            raise ValueError(f"unknown terrain {self.terrain!r}; valid terrains: {', '.join(TERRAIN_KINDS)}")
        if self.action_mode not in ACTION_MODES:
            raise ValueError(f"unknown action mode {self.action_mode!r}; valid modes: {', '.join(ACTION_MODES)}")

    @property
    def eps(self) -> float:
        return DEFAULT_RESIDUAL_SCALE[self.terrain] if self.residual_scale is None else self.residual_scale


# EnvConfig fields that hold a dataclass: given as plain data (a dict of its fields) they are built here,
# so that Gymnasium registrations carry JSON-able kwargs (EnvSpec.to_json / from_json)
_NESTED_CONFIGS = {"noise": ObservationNoise, "physics": PhysicsConfig, "robot": JetHexaSpec, "cpg": CPGParams}


def config_fields(values: dict) -> dict:
    """EnvConfig fields from keyword arguments that may be plain data: a dict for a nested config
    (ObservationNoise, PhysicsConfig, ...), `noise=None` for no observation noise (NO_NOISE)."""
    out = dict(values)
    for name, cls in _NESTED_CONFIGS.items():
        value = out.get(name)
        if name == "noise" and name in out and value is None:
            out[name] = NO_NOISE
        elif isinstance(value, dict):
            out[name] = cls(**value)
    return out


class HexapodEnv(gym.Env):
    """JetHexa locomotion on one terrain family (see module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 60}

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None, **overrides):
        """`config`, or EnvConfig fields as keyword arguments (plain data too: see config_fields), or both:
        the keyword arguments then replace fields of `config`."""
        overrides = config_fields(overrides)
        if config is None:
            config = EnvConfig(**overrides)
        elif overrides:
            config = replace(config, **overrides)
        self.config = config
        self.render_mode = render_mode
        self.sim = Simulation(config.robot, config.physics)
        self.cpg = HopfCPG(config.cpg, dt_s=config.physics.control_dt_s)
        n_act = action_size(config.action_mode)
        self._gait_low, self._gait_high = CPG_PARAM_RANGES.get(config.action_mode, (None, None))
        self._max_turn = STEER_MAX_TURN.get(config.action_mode)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (n_act,), dtype=np.float32)
        self._action_low, self._action_high = np.full(n_act, -1.0), np.full(n_act, 1.0)
        self.observation_space = gym.spaces.Box(-OBS_HIGH, OBS_HIGH, dtype=np.float32)
        self._noise_std = config.noise.std_vector()
        self._noise_on = bool(np.any(self._noise_std > 0))
        self._obs_buffer = np.zeros(OBS_DIM)  # noise-free observation: state part + target
        self._obs_state_part = self._obs_buffer[:60]
        self._noise_block = np.zeros((0, OBS_DIM))  # std * standard normal draws, one row per step
        self._noise_row = 0
        self._control_dt_s = config.physics.control_dt_s
        self._eps = config.eps
        self._weights = TABLE1_WEIGHTS[config.terrain]
        self._joint_mid = (self.sim.joint_upper_rad + self.sim.joint_lower_rad) / 2
        self._joint_half = (self.sim.joint_upper_rad - self.sim.joint_lower_rad) / 2
        stall_steps = (None if config.stall_window_s is None
                       else max(1, round(config.stall_window_s / config.physics.control_dt_s)))
        self._judge = EpisodeJudge(EpisodeRules(
            goal_distance_m=config.goal_distance_m, max_lateral_deviation_m=config.max_lateral_deviation_m,
            fall_tilt_deg=config.fall_tilt_deg, max_steps=config.max_steps, stall_window_steps=stall_steps,
            stall_min_progress_m=config.stall_min_progress_m))
        self.level = config.level  # of the current episode
        self._noise_rng = np.random.default_rng(0)
        self._steps = 0

    # ----------------------------------------------------------------- reset
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        terrain_rng, init_rng, noise_rng = self.np_random.spawn(3)
        cfg = self.config
        self.level = options["level"] if options and "level" in options else cfg.level
        x0 = init_rng.uniform(-cfg.init_xy_jitter_m, cfg.init_xy_jitter_m)
        y0 = init_rng.uniform(-cfg.init_xy_jitter_m, cfg.init_xy_jitter_m)
        yaw0 = init_rng.uniform(-cfg.init_yaw_jitter_rad, cfg.init_yaw_jitter_rad)
        self.sim.load(make_terrain(cfg.terrain, self.level), terrain_rng, (x0, y0), yaw0)
        self._noise_rng = noise_rng
        self._noise_row = len(self._noise_block)  # nothing drawn yet from the new generator
        self.cpg.set_params(cfg.cpg)
        self.cpg.reset()
        self._steps = 0
        state = self.sim.state()
        self.start_xy = state.base_pos_m[:2].copy()
        self.target_xy = self.start_xy + np.array([cfg.goal_distance_m, 0.0])
        (self._start_x, self._start_y), (self._target_x, self._target_y) = self.start_xy.tolist(), self.target_xy.tolist()
        self._judge.reset()
        self._delta = difficulty_factor(cfg.terrain, self.level)
        self._slope_deg_at = self.sim.terrain.slope_deg_at
        self._obs_buffer[60:62] = self.target_xy
        self._state = state
        info = {"level": self.level, "start_xy": self.start_xy.copy(), "target_xy": self.target_xy.copy()}
        return self._observe(state), info

    # ------------------------------------------------------------------ step
    def joint_targets(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(a_t, a_c, a_r) for an action: the joint targets sent, the CPG part and the policy part [rad]."""
        mode = self.config.action_mode
        if mode == "joint":
            a_t = self._joint_mid + self._joint_half * action
            return a_t, np.zeros(NUM_JOINTS), a_t
        if self._gait_low is not None:  # cpg_params, cpg_params_wide, cpg_params_steer
            params = self._gait_low + (action[:4] + 1.0) * 0.5 * (self._gait_high - self._gait_low)
            self.cpg.set_params(self.config.cpg.with_gait(*params))
            a_c = self.cpg.step()
            if self._max_turn is None:
                return a_c, a_c, np.zeros(NUM_JOINTS)
            a_t = a_c.copy()  # the turn: each side's hip stride scaled, (1 + u) right, (1 - u) left
            a_t[0::3] *= 1.0 + LEG_SIDE * (self._max_turn * float(action[4]))
            return a_t, a_c, a_t - a_c
        a_c = self.cpg.step()
        return a_c + self._eps * action, a_c, action

    def step(self, action):
        # The hot path (target: env step at most 1.15x raw physics). Every numpy call costs about
        # a microsecond whatever the array size, so this does as few as give the same numbers:
        # the clip ufunc instead of np.minimum/np.maximum pairs, plain floats for the scalars.
        action = action.astype(np.float64) if type(action) is np.ndarray else np.asarray(action, dtype=np.float64)
        if action.shape != self.action_space.shape:
            raise ValueError(f"action has shape {action.shape}; expected {self.action_space.shape}")
        if not math.isfinite(_add_reduce(action)) and not np.all(np.isfinite(action)):
            raise ValueError("action contains NaN or infinite values")
        a_t, a_c, a_r = self.joint_targets(clip_ufunc(action, self._action_low, self._action_high))
        sim = self.sim
        sent = sim.send_targets(a_t)
        sim.step_physics()
        self._steps += 1
        state = sim.state()
        self._state = state
        x, y, z, _, _, _, _, _, pitch, yaw = state.values[54:64].tolist()  # base xyz, quaternion, rpy
        progress = x - self._start_x
        lateral = y - self._start_y
        reason = self._judge.end_reason(step=self._steps, progress_m=progress, lateral_m=lateral, up_z=state.up_z)
        fell = reason == "fall"
        truncated = reason == "step_limit"
        terminated = reason is not None and not truncated

        dx, dy = self._target_x - x, self._target_y - y
        heading_error = (math.atan2(dy, dx) - yaw + math.pi) % (2 * math.pi) - math.pi
        terms = reward_terms(
            distance_m=math.hypot(dx, dy), heading_error_rad=heading_error, fell=fell,
            pitch_up_deg=-math.degrees(pitch), ground_slope_deg=self._slope_deg_at(x),
            base_height_cm=100.0 * z, step_limit_exceeded=truncated,
        )
        reward = total_reward(terms, self._weights, self._delta)
        info = {  # the CPG's a_c may be its cached read-only trajectory, a_t the simulation's command: copies
            "progress_m": progress, "lateral_m": lateral, "end_reason": reason, "level": self.level,
            "reward_terms": terms, "a_c": a_c.copy(), "a_r": a_r, "a_t": sent.copy(),
            "sim_time_s": self._steps * self._control_dt_s,
        }
        if reason is not None:
            info["is_success"] = reason == "success"
        return self._observe(state), reward, terminated, truncated, info

    @property
    def robot_state(self):
        """The noise-free robot state after the last reset/step (for metrics and recording)."""
        return self._state

    @property
    def sim_time_s(self) -> float:
        return self._steps * self._control_dt_s

    # ------------------------------------------------------------ observation
    def _observe(self, state) -> np.ndarray:
        base = self._obs_buffer  # [60:62] holds the target, written at reset
        state.values.take(_OBS_FROM_STATE, out=self._obs_state_part)  # joints, base xyz, base rpy
        if self._noise_on:
            k = self._noise_row
            if k == len(self._noise_block):
                self._noise_block = self._noise_std * self._noise_rng.standard_normal((_NOISE_BLOCK_STEPS, OBS_DIM))
                k = 0
            self._noise_row = k + 1
            obs = base + self._noise_block[k]
        else:
            obs = base.copy()
        return clip_ufunc(obs, _OBS_LOW_64, _OBS_HIGH_64, out=obs).astype(np.float32)

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from hexbench.world.camera import follow_camera_image

        return follow_camera_image(self.sim)

    def close(self):
        self.sim.close()
