"""Every registered hexbench id: `gymnasium.make` works, Gymnasium's `check_env` passes with no warnings,
the registration is plain data (EnvSpec JSON round trip) with the task's step limit.

The default run builds and checks a representative set of ids (every action mode on flat ground,
each curriculum, the easiest and hardest full-run level of each terrain, the hardest mixed-course
level); the other levels, which differ from those only in their numbers, run with `-m slow`.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import EnvSpec
from gymnasium.utils.env_checker import check_env

import hexbench  # noqa: F401  (registers the ids)
from hexbench.suite.tasks import MODE_IDS, load_suite, registered_ids
from hexbench.world.env import ACTION_MODES

IDS = registered_ids()
SUITE = load_suite("v1")


def _representative_ids() -> set[str]:
    ids = set()
    for mode in ACTION_MODES:
        m = MODE_IDS[mode]
        ids.add(f"hexbench/Flat-{m}-v1")
        for terrain in SUITE.terrains:
            levels = [t for t in SUITE.tasks if t.terrain == terrain]
            ids.add(f"hexbench/{terrain.capitalize()}-Curriculum-{m}-v1")
            ids |= {levels[0].gym_id(mode), levels[-1].gym_id(mode)}
        ids.add(SUITE.extra_tasks[-1].gym_id(mode))
    return ids


REPRESENTATIVE = _representative_ids()
# every id; those outside REPRESENTATIVE only with `-m slow` (some 0.4 s each to build and check)
SWEEP = [env_id if env_id in REPRESENTATIVE else pytest.param(env_id, marks=pytest.mark.slow) for env_id in IDS]


def test_the_default_run_checks_every_kind_of_id() -> None:
    assert REPRESENTATIVE <= set(IDS)
    assert len(REPRESENTATIVE) == len(ACTION_MODES) * (1 + 3 * len(SUITE.terrains) + 1)
    for kind in ("Flat", "Curriculum", "Rough", "Slopes", "Stairs", "Mixed"):
        for m in MODE_IDS.values():
            assert any(kind in i and f"-{m}-" in i for i in REPRESENTATIVE), (kind, m)


def test_every_suite_level_curriculum_and_flat_is_registered_for_every_mode() -> None:
    expected = set()
    for mode in ACTION_MODES:
        m = MODE_IDS[mode]
        expected |= {task.gym_id(mode) for task in SUITE.all_tasks}
        expected |= {f"hexbench/{t}-Curriculum-{m}-v1" for t in ("Rough", "Slopes", "Stairs")}
        expected.add(f"hexbench/Flat-{m}-v1")
    assert set(IDS) == expected
    assert len(IDS) == len(ACTION_MODES) * (len(SUITE.all_tasks) + 3 + 1) == 250  # 43 full-run levels + 3 mixed-course levels
    assert "hexbench/Stairs-5.5cm-CpgResidual-v1" in IDS
    assert "hexbench/Slopes-24deg-Joint-v1" in IDS
    assert "hexbench/Rough-3cm-CpgParams-v1" in IDS


# check_env says this of every wrapped env; it is the only warning allowed
WRAPPED_ENV_NOTICE = ".*is different from the unwrapped version"


@pytest.mark.parametrize("env_id", SWEEP)
def test_check_env_passes_without_warnings(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning from Gymnasium's checkers fails the test
        env = gym.make(env_id)
        try:
            check_env(env.unwrapped, skip_render_check=True)
            with warnings.catch_warnings():  # and the wrapped env gym.make returns (time limit, curriculum)
                warnings.filterwarnings("ignore", message=WRAPPED_ENV_NOTICE)
                check_env(env, skip_render_check=True)
            # and stepping through the wrappers gym.make adds (passive checker, order enforcing, time limit)
            obs, _ = env.reset(seed=0)
            assert env.observation_space.contains(obs)
            for _ in range(3):
                obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
                assert env.observation_space.contains(obs)
                assert np.isfinite(reward) and isinstance(terminated, bool) and isinstance(truncated, bool)
        finally:
            env.close()


@pytest.mark.parametrize("env_id", ["hexbench/Flat-CpgResidual-v1", "hexbench/Stairs-8cm-Joint-v1"])
def test_render_check_passes(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, render_mode="rgb_array")
        try:
            check_env(env.unwrapped)
        finally:
            env.close()


def test_registered_config_is_the_task_spec() -> None:
    task = SUITE.task("stairs", 6.5)
    env = gym.make(task.gym_id("cpg_residual"))
    try:
        cfg = env.unwrapped.config
        assert (cfg.terrain, cfg.level, cfg.action_mode) == ("stairs", 6.5, "cpg_residual")
        assert cfg.max_steps == task.max_steps == 4000
        assert cfg.goal_distance_m == 2.5 and cfg.max_lateral_deviation_m == 0.8
        assert cfg.stall_window_s == task.stall_window_s
        assert cfg.eps == 0.3
    finally:
        env.close()


def test_every_registration_round_trips_through_json() -> None:
    for env_id in IDS:
        spec = gym.spec(env_id)
        assert EnvSpec.from_json(spec.to_json()) == spec, env_id


@pytest.mark.parametrize("env_id", SWEEP)
def test_registration_from_json_makes_a_working_env(env_id: str) -> None:
    env = gym.make(EnvSpec.from_json(gym.spec(env_id).to_json()))
    try:
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        for _ in range(3):
            obs, reward, *_ = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs) and np.isfinite(reward)
    finally:
        env.close()


def test_every_id_has_the_tasks_step_limit() -> None:
    limits = {task.gym_id(mode): task.max_steps for task in SUITE.all_tasks for mode in ACTION_MODES}
    for env_id in IDS:
        spec = gym.spec(env_id)
        assert spec.max_episode_steps == limits.get(env_id, 4000) == spec.kwargs["max_steps"], env_id
    assert gym.spec("hexbench/Mixed-2-CpgResidual-v1").max_episode_steps == 8000


@pytest.mark.parametrize("env_id", ["hexbench/Rough-8cm-CpgResidual-v1", "hexbench/Slopes-Curriculum-Joint-v1"])
def test_noise_none_turns_the_observation_noise_off(env_id: str) -> None:
    from hexbench.world.env import NO_NOISE

    env = gym.make(env_id, noise=None)
    try:
        assert env.unwrapped.config.noise == NO_NOISE
        env.reset(seed=0)
        obs, *_ = env.step(np.zeros(env.action_space.shape, np.float32))
        state = env.unwrapped.robot_state
        np.testing.assert_array_equal(obs[:18], state.joint_pos_rad.astype(np.float32))
    finally:
        env.close()
