"""The training curricula (paper 4.1) as a wrapper around the plain env, the registered curriculum
ids, and the training env's view of the curriculum state (what run.json saves and a resume restores)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest

import hexbench  # noqa: F401  (registers the ids)
from hexbench.suite.tasks import CURRICULUM_TERRAINS
from hexbench.training.envs import make_training_env
from hexbench.training.wrappers import CURRICULA, Curriculum, CurriculumWrapper, make_curriculum_env
from hexbench.world.env import HexapodEnv
from hexbench.world.rewards import TABLE1_WEIGHTS, difficulty_factor, total_reward

ZERO18 = np.zeros(18, dtype=np.float32)


def arrive(env: gym.Env, seed: int):
    """Reset, put the robot just past the goal line and step: one arrival."""
    env.reset(seed=seed)
    base = env.unwrapped
    sim = base.sim
    p.resetBasePositionAndOrientation(sim.robot_id, [base.start_xy[0] + 2.55, base.start_xy[1], 0.3],
                                      p.getQuaternionFromEuler((0.0, 0.0, 0.0)), physicsClientId=sim.client)
    return env.step(ZERO18)


def test_curriculum_levels_up_after_20_arrivals_and_stops_at_the_top() -> None:
    env = make_curriculum_env("rough", "cpg_residual", noise=None, curriculum=Curriculum(12.0, 1.0, 13.0))
    try:
        for arrival in range(45):
            level = env.level
            _, reward, _, _, info = arrive(env, arrival)
            assert env.unwrapped.sim.terrain.level == env.unwrapped.level == level
            assert info["end_reason"] == "success"
            expected = total_reward(info["reward_terms"], TABLE1_WEIGHTS["rough"], difficulty_factor("rough", level))
            assert reward == pytest.approx(expected)
            assert env.level == info["level"] == (12.0 if arrival < 19 else 13.0)  # the 20th levels up; 13 is the cap
    finally:
        env.close()


def test_curricula_follow_section_4_1() -> None:
    assert (CURRICULA["rough"].start_level, CURRICULA["rough"].level_step, CURRICULA["rough"].max_level) == (5, 1, 13)
    assert (CURRICULA["slopes"].start_level, CURRICULA["slopes"].level_step) == (5, 3)
    assert CURRICULA["slopes"].max_level <= 18
    assert (CURRICULA["stairs"].start_level, CURRICULA["stairs"].level_step, CURRICULA["stairs"].max_level) == (5, 0.5, 8)
    assert all(c.successes_per_level == 20 for c in CURRICULA.values())
    assert tuple(CURRICULA) == CURRICULUM_TERRAINS  # one registered curriculum id per curriculum


def test_registered_curriculum_id_is_the_wrapped_plain_env() -> None:
    env = gym.make("hexbench/Stairs-Curriculum-Joint-v1")
    try:
        curriculum = next(w for w in _wrappers(env) if isinstance(w, CurriculumWrapper))
        assert curriculum.curriculum == CURRICULA["stairs"]
        assert type(env.unwrapped) is HexapodEnv and env.unwrapped.config.stall_window_s is None
        _, info = env.reset(seed=0)
        assert info["level"] == 5.0
    finally:
        env.close()


def test_no_curriculum_for_flat_ground() -> None:
    with pytest.raises(ValueError, match="terrains with one: rough, slopes, stairs"):
        make_curriculum_env("flat")


def test_training_env_saves_and_restores_the_curriculum_state() -> None:
    env = make_training_env("rough", "cpg_residual", None, curriculum=Curriculum(5.0, 1.0, 13.0))
    fixed = make_training_env("stairs", "cpg_residual", None, fixed_level=6.5)
    try:
        assert env.curriculum_state() == {"level": 5.0, "successes": 0}
        env.set_curriculum_state(9.0, 7)
        assert env.curriculum_state() == {"level": 9.0, "successes": 7}
        _, info = env.reset(seed=1)
        assert info["level"] == env.unwrapped.sim.terrain.level == 9.0
        assert fixed.curriculum_state() == {"level": 6.5, "successes": 0}
        fixed.set_curriculum_state(6.5, 0)
        assert fixed.reset(seed=1)[1]["level"] == 6.5
    finally:
        env.close()
        fixed.close()


def _wrappers(env: gym.Env) -> list[gym.Env]:
    out = []
    while isinstance(env, gym.Wrapper):
        out.append(env)
        env = env.env
    return out


def test_a_heading_hold_training_env_takes_the_gait_alone_held_for_the_decision_interval():
    env = make_training_env("rough", "cpg_params_steer", None, decision_interval_steps=30, heading_hold=True)
    assert env.action_space.shape == (4,)
    env.reset(seed=1)
    _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert info["decision_env_steps"] == 30
    env.close()
