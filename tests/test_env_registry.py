"""Every registered hexbench id: `gymnasium.make` works and Gymnasium's `check_env` passes with no warnings."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import hexbench  # noqa: F401  (registers the ids)
from hexbench.suite.tasks import MODE_IDS, load_suite, registered_ids
from hexbench.world.env import ACTION_MODES

IDS = registered_ids()
SUITE = load_suite("v1")


def test_every_suite_level_curriculum_and_flat_is_registered_for_every_mode() -> None:
    expected = set()
    for mode in ACTION_MODES:
        m = MODE_IDS[mode]
        expected |= {task.gym_id(mode) for task in SUITE.all_tasks}
        expected |= {f"hexbench/{t}-Curriculum-{m}-v1" for t in ("Rough", "Slopes", "Stairs")}
        expected.add(f"hexbench/Flat-{m}-v1")
    assert set(IDS) == expected
    assert len(IDS) == 3 * (len(SUITE.all_tasks) + 3 + 1) == 150  # 43 full-run levels + 3 mixed-course levels
    assert "hexbench/Stairs-5.5cm-CpgResidual-v1" in IDS
    assert "hexbench/Slopes-24deg-Joint-v1" in IDS
    assert "hexbench/Rough-3cm-CpgParams-v1" in IDS


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes_without_warnings(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning from Gymnasium's checkers fails the test
        env = gym.make(env_id)
        try:
            check_env(env.unwrapped, skip_render_check=True)
            # and through the wrappers gym.make adds (passive checker, order enforcing)
            obs, info = env.reset(seed=0)
            assert env.observation_space.contains(obs)
            for _ in range(3):
                obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
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
