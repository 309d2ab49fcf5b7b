"""HexapodEnv behaviour: observation layout and noise, the three action modes, Table 1 rewards with
the eq. 8 difficulty factor, every way an episode ends, the level as reset option, info arrays, and
bad input. (The training curricula and the early-end penalty are wrappers: test_training_wrappers.py.)"""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from hexbench.world.env import (
    CPG_PARAM_HIGH,
    CPG_PARAM_LOW,
    NO_NOISE,
    OBS_DIM,
    EnvConfig,
    HexapodEnv,
    ObservationNoise,
    cpg_params_action,
)
from hexbench.world.rewards import TABLE1_WEIGHTS, difficulty_factor, total_reward

ZERO18 = np.zeros(18, dtype=np.float32)


@pytest.fixture()
def make_env():
    envs: list[HexapodEnv] = []

    def make(**config) -> HexapodEnv:
        config.setdefault("terrain", "flat")
        env = HexapodEnv(EnvConfig(**config))
        envs.append(env)
        return env

    yield make
    for env in envs:
        env.close()


def teleport(env: HexapodEnv, x_m: float, y_m: float, z_m: float | None = None,
             rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    sim = env.sim
    z = sim.state().base_pos_m[2] if z_m is None else z_m
    p.resetBasePositionAndOrientation(sim.robot_id, [x_m, y_m, z], p.getQuaternionFromEuler(rpy_rad),
                                      physicsClientId=sim.client)


# ------------------------------------------------------------------------------------ spaces
@pytest.mark.parametrize("mode, n_act", [("joint", 18), ("cpg_residual", 18), ("cpg_params", 4)])
def test_spaces(make_env, mode: str, n_act: int) -> None:
    env = make_env(action_mode=mode)
    assert env.observation_space.shape == (OBS_DIM,) == (62,)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.shape == (n_act,)
    assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    assert set(info) >= {"start_xy", "target_xy", "level"}


def test_observation_layout_without_noise(make_env) -> None:
    env = make_env(noise=NO_NOISE)
    env.reset(seed=3)
    for _ in range(30):
        obs, *_ = env.step(ZERO18)
    s = env.sim.state()
    expected = np.concatenate([s.joint_pos_rad, s.joint_vel_rad_per_s, s.joint_torque_nm, s.base_pos_m,
                               s.base_rpy_rad, env.target_xy]).astype(np.float32)
    np.testing.assert_array_equal(obs, expected)
    np.testing.assert_allclose(env.target_xy, env.start_xy + [2.5, 0.0])
    assert obs[56] == pytest.approx(0.12, abs=0.02)  # base z: standing height


def test_observation_noise_has_the_documented_standard_deviations(make_env) -> None:
    noise = ObservationNoise()
    noisy, clean = make_env(noise=noise), make_env(noise=NO_NOISE)
    noisy.reset(seed=5)
    clean.reset(seed=5)
    diffs = []
    for _ in range(300):
        a, *_ = noisy.step(ZERO18)
        b, *_ = clean.step(ZERO18)
        diffs.append(a.astype(np.float64) - b)
    diffs = np.array(diffs)
    # noise touches observations only: the simulated robot is the same in both
    np.testing.assert_array_equal(noisy.sim.state().base_pos_m, clean.sim.state().base_pos_m)
    groups = {
        "joint_pos_rad": slice(0, 18), "joint_vel_rad_per_s": slice(18, 36), "joint_torque_nm": slice(36, 54),
        "base_pos_m": slice(54, 57), "base_rpy_rad": slice(57, 60),
    }
    for name, cols in groups.items():
        want = getattr(noise, name)
        assert want > 0
        assert np.std(diffs[:, cols]) == pytest.approx(want, rel=0.1), name
        assert abs(np.mean(diffs[:, cols])) < 0.2 * want, name
    np.testing.assert_array_equal(diffs[:, 60:62], 0.0)  # the target is known exactly


def test_observation_noise_is_one_standard_normal_draw_of_62_per_observation(make_env) -> None:
    """The env draws its noise in blocks of steps (speed); the numbers must be exactly those of one
    `standard_normal(62)` per observation from the noise generator that reset spawns, across blocks
    and across resets."""
    from gymnasium.utils.seeding import np_random

    noise = ObservationNoise()
    std = noise.std_vector()
    env = make_env(noise=noise, terrain="rough", level=5.0)
    env_high = env.observation_space.high.astype(np.float64)
    for seed in (11, 12):
        noise_rng = np_random(seed)[0].spawn(3)[2]  # reset spawns (terrain, init pose, noise)
        obs = env.reset(seed=seed)[0]
        for k in range(75):  # more than two blocks
            s = env.robot_state
            clean = np.concatenate([s.values[0:57], s.base_rpy_rad, env.target_xy])
            want = np.minimum(np.maximum(clean + std * noise_rng.standard_normal(OBS_DIM), -env_high), env_high)
            np.testing.assert_array_equal(obs, want.astype(np.float32), err_msg=f"seed {seed}, step {k}")
            obs, *_ = env.step(ZERO18)


# ------------------------------------------------------------------------------ action modes
def test_joint_mode_maps_the_unit_box_onto_the_joint_limits(make_env) -> None:
    env = make_env(action_mode="joint")
    env.reset(seed=0)
    low, high = env.sim.joint_lower_rad, env.sim.joint_upper_rad
    np.testing.assert_allclose(env.joint_targets(-np.ones(18))[0], low)
    np.testing.assert_allclose(env.joint_targets(np.ones(18))[0], high)
    np.testing.assert_allclose(env.joint_targets(np.zeros(18))[0], (low + high) / 2)
    # held long enough, the joints get there (free-swinging hip joints, so no load in the way)
    action = np.tile([0.5, 0.0, 0.0], 6).astype(np.float32)
    for _ in range(60):
        env.step(action)
    target_hip = low[0] + 0.75 * (high[0] - low[0])
    np.testing.assert_allclose(env.sim.state().joint_pos_rad[0::3], target_hip, atol=0.05)


@pytest.mark.parametrize("terrain, eps", [("rough", 0.6), ("slopes", 0.4), ("stairs", 0.3)])
def test_residual_scale_defaults_to_the_papers_eps(make_env, terrain: str, eps: float) -> None:
    assert EnvConfig(terrain=terrain).eps == eps
    assert EnvConfig(terrain=terrain, residual_scale=0.25).eps == 0.25
    env = make_env(terrain=terrain, level=SUITE_LOWEST[terrain], action_mode="cpg_residual")
    env.reset(seed=1)
    a_r = np.random.default_rng(0).uniform(-1, 1, 18)
    a_t, a_c, a_r_out = env.joint_targets(a_r)
    np.testing.assert_allclose(a_t, a_c + eps * a_r)
    np.testing.assert_array_equal(a_r_out, a_r)


SUITE_LOWEST = {"rough": 3.0, "slopes": 6.0, "stairs": 2.0, "flat": 0.0}


def test_residual_zero_sends_exactly_the_cpg_signal(make_env) -> None:
    """With a_r = 0 the servos get the CPG's angles: at first through the servo speed limit (the
    robot starts at zero angles, the CPG at hip +-A1), then exactly."""
    env = make_env(action_mode="cpg_residual")
    env.reset(seed=2)
    max_step = env.config.robot.servo_max_speed_rad_per_s * env.config.physics.control_dt_s
    previous = np.zeros(18)
    for k in range(120):
        _, _, _, _, info = env.step(ZERO18)
        np.testing.assert_array_equal(info["a_r"], 0.0)
        assert np.abs(info["a_t"] - previous).max() <= max_step + 1e-12
        previous = info["a_t"]
        if k >= 10:
            wanted = np.clip(info["a_c"], env.sim.joint_lower_rad, env.sim.joint_upper_rad)
            np.testing.assert_allclose(info["a_t"], wanted, atol=1e-9)


@pytest.mark.parametrize("action, expected", [
    (-1.0, (math.pi / 2, -1.0, -0.5, -1.0)),
    (1.0, (math.pi, 1.0, 1.0, 0.5)),
    (0.0, (0.75 * math.pi, 0.0, 0.25, -0.25)),
])
def test_cpg_params_mode_maps_onto_the_paper_ranges(make_env, action: float, expected) -> None:
    np.testing.assert_allclose(CPG_PARAM_LOW, (math.pi / 2, -1.0, -0.5, -1.0))
    np.testing.assert_allclose(CPG_PARAM_HIGH, (math.pi, 1.0, 1.0, 0.5))
    env = make_env(action_mode="cpg_params")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.full(4, action, dtype=np.float32))
    params = env.cpg.params
    got = (params.omega_swing_rad_per_s, params.hip_amplitude_rad, params.knee_amplitude_rad, params.ankle_amplitude_rad)
    np.testing.assert_allclose(got, expected)
    np.testing.assert_array_equal(info["a_c"], env.cpg.joint_angles())
    np.testing.assert_array_equal(info["a_r"], 0.0)


def test_the_wide_gait_mode_reaches_the_cpgs_own_gait_which_the_papers_ranges_clip(make_env) -> None:
    """cpg_params_wide: A2 up to 1.2 and A3 up to 1.0, so the HRL action for the CPG's gait (section
    2.2: omega pi, A1 0.45, A2 1.2, A3 1.0) drives the CPG as it walks on its own; cpg_params clips
    A2 and A3 to 1.0 and 0.5."""
    gait = (math.pi, 0.45, 1.2, 1.0)
    cpg = make_env(action_mode="cpg_residual")
    cpg.reset(seed=3)
    clipped, wide = make_env(action_mode="cpg_params"), make_env(action_mode="cpg_params_wide")
    clipped.reset(seed=3)
    wide.reset(seed=3)
    clipped_off_rad = 0.0
    for _ in range(120):  # two seconds: one gait cycle
        _, _, _, _, own = cpg.step(np.zeros(18, dtype=np.float32))
        _, _, _, _, held = wide.step(np.asarray(cpg_params_action(*gait, "cpg_params_wide"), dtype=np.float32))
        _, _, _, _, paper = clipped.step(np.asarray(cpg_params_action(*gait), dtype=np.float32))
        np.testing.assert_allclose(held["a_t"], own["a_t"], atol=1e-6)  # float32 actions: A1 0.45 to 1e-8
        clipped_off_rad = max(clipped_off_rad, float(np.max(np.abs(paper["a_t"] - own["a_t"]))))
    p = wide.cpg.params
    np.testing.assert_allclose((p.knee_amplitude_rad, p.ankle_amplitude_rad), (1.2, 1.0))
    p = clipped.cpg.params
    np.testing.assert_allclose((p.knee_amplitude_rad, p.ankle_amplitude_rad), (1.0, 0.5))
    assert clipped_off_rad > 0.1  # the knee and ankle swing less than the CPG's
    assert wide.action_space.shape == (4,)


def test_the_steering_mode_turns_the_cpgs_gait_by_scaling_each_sides_hip_stride(make_env) -> None:
    """cpg_params_steer: the wide gait ranges plus a turn u = 0.3 a[4]; with no turn it sends the
    CPG's joint targets, with a turn the right hips swing (1 + u) and the left (1 - u) times the
    CPG's, knees and ankles untouched (info's a_r: the targets less the CPG's), and the robot turns
    left for u > 0."""
    gait = (math.pi, 0.45, 1.2, 1.0)
    cpg, straight, left = (make_env(action_mode=m) for m in ("cpg_residual", "cpg_params_steer", "cpg_params_steer"))
    for env in (cpg, straight, left):
        env.reset(seed=3)
    no_turn = np.asarray(cpg_params_action(*gait, "cpg_params_steer"), dtype=np.float32)
    turn = np.asarray(cpg_params_action(*gait, "cpg_params_steer", turn=0.2), dtype=np.float32)
    assert straight.action_space.shape == (5,) and no_turn[4] == 0.0 and turn[4] == pytest.approx(2 / 3)
    for _ in range(240):  # four seconds: two gait cycles
        _, _, _, _, own = cpg.step(np.zeros(18, dtype=np.float32))
        _, _, _, _, held = straight.step(no_turn)
        obs, _, _, _, turning = left.step(turn)
        np.testing.assert_allclose(held["a_t"], own["a_t"], atol=1e-6)
        np.testing.assert_allclose(turning["a_c"], own["a_c"], atol=1e-6)
        side = np.repeat([1.0, 1.0, 1.0, -1.0, -1.0, -1.0], 3) * np.tile([1.0, 0.0, 0.0], 6)
        np.testing.assert_allclose(turning["a_r"], own["a_c"] * 0.2 * side, atol=1e-6)  # a_t - a_c, before sending
    assert obs[59] > 0.15  # yaw [rad]: it turned left
    assert cpg_params_action(*gait, "cpg_params_steer", turn=1.0)[4] == 1.0  # a turn beyond 0.3 is clipped


# -------------------------------------------------------------------------------- reward
def test_table1_weights() -> None:
    w = TABLE1_WEIGHTS
    as_rows = {t: (w[t].distance, w[t].heading, w[t].fall, w[t].tilt, w[t].height, w[t].step_limit)
               for t in ("rough", "slopes", "stairs")}
    assert as_rows == {
        "rough": (3, 1, 0.1, 0, 0, 1),
        "slopes": (2, 0.2, 0.1, 0.01, 0, 1),
        "stairs": (1, 0.2, 0.2, 0, 0.01, 1),
    }


@pytest.mark.parametrize("terrain, level, delta", [
    ("rough", 3, 0.0), ("rough", 5, 0.0), ("rough", 6, 0.1), ("rough", 13, 0.8),
    ("slopes", 5, 0.0), ("slopes", 8, 0.1), ("slopes", 17, 0.4),
    ("stairs", 5, 0.0), ("stairs", 5.5, 0.1), ("stairs", 8, 0.6), ("flat", 0, 0.0),
])
def test_difficulty_factor_of_eq_8(terrain: str, level: float, delta: float) -> None:
    """+0.1 per 1 cm (rough), per 3 deg (slopes), per 0.5 cm (stairs) above the curriculum start."""
    assert difficulty_factor(terrain, level) == pytest.approx(delta)


@pytest.mark.parametrize("terrain, level", [("rough", 8.0), ("slopes", 11.0), ("stairs", 6.0)])
def test_step_reward_is_the_weighted_table1_sum_times_one_plus_delta(make_env, terrain: str, level: float) -> None:
    env = make_env(terrain=terrain, level=level, noise=NO_NOISE)
    env.reset(seed=4)
    delta = difficulty_factor(terrain, level)
    assert delta > 0
    for _ in range(50):
        _, reward, _, _, info = env.step(ZERO18)
        terms = info["reward_terms"]
        assert reward == pytest.approx(total_reward(terms, TABLE1_WEIGHTS[terrain], delta))
        w = TABLE1_WEIGHTS[terrain]
        plain = (w.distance * terms["distance"] + w.heading * terms["heading"] + w.fall * terms["fall"]
                 + w.tilt * terms["tilt"] + w.height * terms["height"] + w.step_limit * terms["step_limit"])
        assert reward == pytest.approx((1 + delta) * plain)
    s = env.sim.state()
    d = float(np.hypot(*(env.target_xy - s.base_pos_m[:2])))
    assert terms["distance"] == pytest.approx(1 / d - 1)
    assert terms["fall"] == 0 and terms["step_limit"] == 0
    assert 0.0 <= terms["heading"] <= 1.0


def test_height_reward_pays_above_12_cm_on_stairs(make_env) -> None:
    env = make_env(terrain="stairs", level=5.0, noise=NO_NOISE)
    env.reset(seed=0)
    teleport(env, 1.7, 0.0, z_m=0.20 + 0.125)  # on the fourth step: ground 20 cm, body ~32 cm up
    _, _, _, _, info = env.step(ZERO18)
    z_cm = 100 * env.sim.state().base_pos_m[2]
    assert info["reward_terms"]["height"] == pytest.approx(z_cm - 12.0)
    assert info["reward_terms"]["height"] > 15


# --------------------------------------------------------------------------- episode end
def test_fall_terminates_with_the_stability_penalty(make_env) -> None:
    env = make_env(noise=NO_NOISE)
    env.reset(seed=0)
    teleport(env, 0.0, 0.0, z_m=0.3, rpy_rad=(math.radians(70), 0.0, 0.0))
    _, reward, terminated, truncated, info = env.step(ZERO18)
    assert terminated and not truncated
    assert info["end_reason"] == "fall" and info["is_success"] is False
    assert info["reward_terms"]["fall"] == -100.0
    assert reward < -9  # 0.1 * -100 dominates


def test_a_tilt_below_60_degrees_is_not_a_fall(make_env) -> None:
    env = make_env(noise=NO_NOISE)
    env.reset(seed=0)
    teleport(env, 0.0, 0.0, z_m=0.3, rpy_rad=(math.radians(45), 0.0, 0.0))
    _, _, terminated, _, info = env.step(ZERO18)
    assert not terminated and info["end_reason"] is None


def test_lateral_deviation_beyond_0_8_m_terminates(make_env) -> None:
    env = make_env(noise=NO_NOISE)
    env.reset(seed=0)
    teleport(env, env.start_xy[0] + 1.0, env.start_xy[1] - 0.85)
    _, _, terminated, truncated, info = env.step(ZERO18)
    assert terminated and not truncated and info["end_reason"] == "lateral_deviation"
    assert info["is_success"] is False


def test_goal_reached_2_5_m_ahead_is_success(make_env) -> None:
    env = make_env(noise=NO_NOISE)
    env.reset(seed=0)
    teleport(env, env.start_xy[0] + 2.52, env.start_xy[1] + 0.3)
    _, _, terminated, truncated, info = env.step(ZERO18)
    assert terminated and not truncated
    assert info["end_reason"] == "success" and info["is_success"] is True
    assert info["progress_m"] >= 2.5


def test_crossing_the_goal_line_too_far_sideways_is_not_success(make_env) -> None:
    env = make_env(noise=NO_NOISE)
    env.reset(seed=0)
    teleport(env, env.start_xy[0] + 2.6, env.start_xy[1] + 0.9)
    _, _, _, _, info = env.step(ZERO18)
    assert info["end_reason"] == "lateral_deviation"


def test_step_limit_truncates_with_the_step_penalty(make_env) -> None:
    env = make_env(noise=NO_NOISE, max_steps=5)
    env.reset(seed=0)
    for k in range(1, 6):
        _, _, terminated, truncated, info = env.step(ZERO18)
        assert not terminated
        assert truncated == (k == 5)
    assert info["end_reason"] == "step_limit" and info["is_success"] is False
    assert info["reward_terms"]["step_limit"] == -10.0
    assert EnvConfig(terrain="flat").max_steps == 4000


def test_stall_rule_ends_an_episode_that_makes_no_progress(make_env) -> None:
    env = make_env(noise=NO_NOISE, action_mode="joint", stall_window_s=0.5)
    env.reset(seed=0)
    stand = np.tile([0.0, 0.0, 0.0], 6).astype(np.float32)
    stand[1::3] = -(env.sim.joint_upper_rad[1] + env.sim.joint_lower_rad[1]) / (
        env.sim.joint_upper_rad[1] - env.sim.joint_lower_rad[1])  # knee target 0
    stand[2::3] = -(env.sim.joint_upper_rad[2] + env.sim.joint_lower_rad[2]) / (
        env.sim.joint_upper_rad[2] - env.sim.joint_lower_rad[2])  # ankle target 0
    for k in range(1, 200):
        _, _, terminated, _, info = env.step(stand)
        if terminated:
            break
    assert info["end_reason"] == "stalled"
    assert k == pytest.approx(0.5 * 60, abs=2)  # right after one 0.5 s window


def test_no_stall_rule_by_default(make_env) -> None:
    assert EnvConfig(terrain="flat").stall_window_s is None


# --------------------------------------------------------------------------------- level
def test_a_reset_option_sets_the_level_of_that_episode_only(make_env) -> None:
    env = make_env(terrain="rough", level=6.0, noise=NO_NOISE)
    _, info = env.reset(seed=0, options={"level": 11.0})
    assert info["level"] == env.level == env.sim.terrain.level == 11.0
    _, _, _, _, info = env.step(ZERO18)
    assert info["level"] == 11.0
    _, info = env.reset(seed=0)
    assert info["level"] == env.sim.terrain.level == 6.0


def test_the_env_has_no_training_options() -> None:
    from dataclasses import fields

    assert not {"curriculum", "early_end_penalty"} & {f.name for f in fields(EnvConfig)}


def test_plain_data_keyword_arguments_build_the_nested_configs() -> None:
    env = HexapodEnv(terrain="flat", noise={"joint_pos_rad": 0.5}, max_steps=10)
    quiet = HexapodEnv(terrain="flat", noise=None)
    try:
        assert env.config.noise == ObservationNoise(joint_pos_rad=0.5) and env.config.max_steps == 10
        assert quiet.config.noise == NO_NOISE
    finally:
        env.close()
        quiet.close()


# -------------------------------------------------------------------------------- info
@pytest.mark.parametrize("mode", ["joint", "cpg_residual", "cpg_params"])
def test_info_arrays_are_fresh_writeable_copies_each_step(make_env, mode: str) -> None:
    env = make_env(action_mode=mode, noise=NO_NOISE)
    action = np.zeros(env.action_space.shape, np.float32)
    for seed in (0, 0):  # the second episode replays the CPG's cached trajectory
        env.reset(seed=seed)
        _, _, _, _, first = env.step(action)
        kept = {k: first[k].copy() for k in ("a_c", "a_r", "a_t")}
        _, _, _, _, second = env.step(action)
        for key in ("a_c", "a_r", "a_t"):
            assert first[key] is not second[key] and first[key].flags.writeable, key
            np.testing.assert_array_equal(first[key], kept[key], err_msg=key)
        first["a_t"][:] = 99.0  # writing into an info array does not reach the simulation
        _, _, _, _, third = env.step(action)
        assert np.all(np.abs(third["a_t"]) < 10)


# ------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("bad, message", [
    (np.zeros(17), "shape"),
    (np.zeros((1, 18)), "shape"),
    (np.array([np.nan] + [0.0] * 17), "NaN"),
    (np.array([np.inf] + [0.0] * 17), "infinite"),
])
def test_bad_actions_are_rejected_with_a_clear_message(make_env, bad: np.ndarray, message: str) -> None:
    env = make_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(bad)


def test_out_of_range_actions_are_clipped_to_the_unit_box(make_env) -> None:
    a, b = make_env(noise=NO_NOISE), make_env(noise=NO_NOISE)
    a.reset(seed=0)
    b.reset(seed=0)
    big = np.full(18, 5.0)
    for _ in range(20):
        oa, *_ = a.step(big)
        ob, *_ = b.step(np.ones(18))
    np.testing.assert_array_equal(oa, ob)


@pytest.mark.parametrize("field, value, valid", [
    ("terrain", "lava", "valid terrains: flat, rough, slopes, stairs"),
    ("action_mode", "torque", "valid modes: joint, cpg_residual, cpg_params"),
])
def test_bad_config_names_the_valid_choices(field: str, value: str, valid: str) -> None:
    config = {"terrain": "flat", field: value}
    with pytest.raises(ValueError, match=valid):
        EnvConfig(**config)


def test_render_returns_an_rgb_image(make_env) -> None:
    env = HexapodEnv(EnvConfig(terrain="flat"), render_mode="rgb_array")
    try:
        env.reset(seed=0)
        image = env.render()
        assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
        assert image.std() > 5  # not a blank frame
    finally:
        env.close()
