"""Heading hold (hexbench.agents.heading): the turn law, the hip-only residual, and that it steers the robot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hexbench.agents.heading import BASE_Y_INDEX, BASE_YAW_INDEX, TARGET_Y_INDEX, HeadingHold, HeadingSteering
from hexbench.suite.rollout import LocalActor, play
from hexbench.suite.tasks import load_suite
from hexbench.world.cpg import HopfCPG


def _obs(y_m: float = 0.0, yaw_rad: float = 0.0, target_y_m: float = 0.0) -> np.ndarray:
    obs = np.zeros(62, dtype=np.float32)
    obs[BASE_Y_INDEX], obs[BASE_YAW_INDEX], obs[TARGET_Y_INDEX] = y_m, yaw_rad, target_y_m
    return obs


def test_turns_towards_the_centre_line_and_limits_the_turn():
    hold = HeadingHold(gain=1.0, max_turn=0.3, lookahead_m=1.0)
    assert hold.turn(_obs()) == 0.0
    assert hold.turn(_obs(y_m=-0.1)) > 0  # right of the line: turn left
    assert hold.turn(_obs(y_m=0.1)) < 0
    assert hold.turn(_obs(yaw_rad=0.1)) == pytest.approx(-0.1)  # on the line, facing left: turn right
    assert hold.turn(_obs(yaw_rad=2.0)) == -0.3
    assert hold.turn(_obs(yaw_rad=-3.0)) == 0.3
    assert hold.turn(_obs(y_m=0.5, target_y_m=0.5)) == 0.0  # the line runs through the target
    assert hold.turn(_obs(yaw_rad=2 * math.pi)) == pytest.approx(0.0, abs=1e-6)  # angles wrap


@pytest.mark.parametrize("bad", [{"gain": -1.0}, {"max_turn": 1.0}, {"lookahead_m": 0.0}])
def test_refuses_settings_that_cannot_steer(bad):
    with pytest.raises(ValueError, match="HeadingHold needs"):
        HeadingHold(**bad)


def test_touches_only_the_hips_in_proportion_to_the_cpg_stride():
    task = load_suite("v1").task("mixed", 1)
    steering = HeadingSteering.for_task(HeadingHold(max_turn=0.3), task)
    cfg = task.env_config("cpg_residual")
    twin = HopfCPG(cfg.cpg, cfg.physics.control_dt_s)
    twin.reset()
    for _ in range(40):
        residual = steering.residual(_obs(y_m=-1.0))  # far right of the line: full left turn
        a_c = twin.step()
        hips = residual[0::3] * cfg.eps
        assert np.allclose(hips, [0.3 * a_c[0], 0.3 * a_c[3], 0.3 * a_c[6], -0.3 * a_c[9], -0.3 * a_c[12], -0.3 * a_c[15]])
        assert not residual[1::3].any() and not residual[2::3].any()
    steering.reset()
    twin.reset()
    assert np.allclose(steering.residual(_obs(y_m=-1.0))[0::3] * cfg.eps / 0.3, twin.step()[0::3] * [1, 1, 1, -1, -1, -1])


class HeldCPG:
    action_mode = "cpg_residual"

    def __init__(self, steering: HeadingSteering | None):
        self.steering = steering

    def reset(self, seed: int) -> None:
        if self.steering is not None:
            self.steering.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self.steering is None:
            return np.zeros(18, dtype=np.float32)
        return np.clip(self.steering.residual(obs), -1, 1).astype(np.float32)


def test_brings_a_robot_that_starts_askew_back_on_its_heading():
    task = load_suite("v1").task("rough", 3)
    askew = {"init_yaw_jitter_rad": 0.35}  # uniform +-0.35 rad start heading
    ends = {}
    for name, steering in (("open loop", None), ("held", HeadingSteering.for_task(HeadingHold(), task))):
        actor = LocalActor(HeldCPG(steering))
        yaws = []
        original = actor.act

        def act(obs, step, original=original, yaws=yaws):
            yaws.append(float(obs[BASE_YAW_INDEX]))
            return original(obs, step)

        actor.act = act
        episode = play(task, 4242, actor, max_steps=1500, **askew)
        ends[name] = (abs(yaws[0]), abs(yaws[-1]), episode.row["max_abs_y_m"])
    start_yaw = ends["held"][0]
    assert start_yaw > 0.1  # this seed starts askew
    assert ends["held"][1] < 0.1 < ends["open loop"][1]
    assert ends["held"][2] < ends["open loop"][2]


def test_a_steering_modes_turn_value_is_the_holds_turn_in_action_units():
    from hexbench.agents.heading import turn_action_value, with_held_heading

    hold = HeadingHold(gain=1.0, max_turn=0.3, lookahead_m=1.0)
    assert turn_action_value(hold, _obs(yaw_rad=0.1), "cpg_params_steer") == pytest.approx(-0.1 / 0.3)
    assert turn_action_value(hold, _obs(yaw_rad=-2.0), "cpg_params_steer") == 1.0
    action = with_held_heading(np.array([0.1, 0.2, 0.3, 0.4]), hold, _obs(yaw_rad=0.1), "cpg_params_steer")
    assert action.shape == (5,) and np.allclose(action[:4], [0.1, 0.2, 0.3, 0.4])
    with pytest.raises(ValueError, match="has no turn; steering modes: cpg_params_steer"):
        turn_action_value(hold, _obs(), "cpg_params_wide")


def test_the_heading_turn_env_takes_the_gait_alone_and_turns_by_the_hold_at_every_control_step():
    from hexbench.agents.heading import HeadingTurn
    from hexbench.world.cpg import LEG_SIDE
    from hexbench.world.env import HexapodEnv, cpg_params_action

    with pytest.raises(ValueError, match="HeadingTurn needs a steering action mode"):
        HeadingTurn(HexapodEnv(terrain="flat", action_mode="cpg_params_wide"))
    env = HeadingTurn(HexapodEnv(terrain="flat", action_mode="cpg_params_steer"))
    assert env.action_space.shape == (4,)
    gait = np.asarray(cpg_params_action(math.pi, 0.45, 1.2, 1.0, "cpg_params_wide"), dtype=np.float32)
    obs, _ = env.reset(seed=3)
    turns = []
    for _ in range(90):
        u = env.hold.turn(obs)  # the turn the step must apply, from the observation before it
        obs, _, terminated, truncated, info = env.step(gait)
        turns.append(u)
        turned, cpg_hips = info["a_r"][0::3], info["a_c"][0::3]  # a_r = a_t - a_c: the turn's part of the hips
        assert np.allclose(turned, cpg_hips * LEG_SIDE * u, atol=1e-9)
        assert not (terminated or truncated)
    assert len({round(u, 6) for u in turns}) > 10  # the turn follows the heading, step by step
    env.close()
