"""The training reward option `early_end_penalty` (hexbench.training.wrappers.EarlyEndPenalty): an
early end other than success never pays."""

import numpy as np
import pytest

from hexbench.training.wrappers import EarlyEndPenalty, early_end_penalty
from hexbench.world.env import EnvConfig, HexapodEnv
from hexbench.world.rewards import TABLE1_WEIGHTS, difficulty_factor


def _first_end(penalty: bool, **rules):
    env = HexapodEnv(EnvConfig(terrain="rough", level=7, **rules))
    env = EarlyEndPenalty(env) if penalty else env
    env.reset(seed=5)
    try:
        for _ in range(600):
            _, reward, terminated, truncated, info = env.step(np.zeros(18, np.float32))
            if terminated or truncated:
                return reward, info["end_reason"]
    finally:
        env.close()
    raise AssertionError("episode did not end")


def test_leaving_the_corridor_costs_the_discounted_worst_case_of_staying():
    plain, reason = _first_end(False, max_lateral_deviation_m=0.002)
    penalised, reason2 = _first_end(True, max_lateral_deviation_m=0.002)
    assert reason == reason2 == "lateral_deviation"
    expected = (1 + difficulty_factor("rough", 7)) * -TABLE1_WEIGHTS["rough"].distance / (1 - 0.99)
    assert penalised - plain == pytest.approx(expected)
    # r_d = 1/d - 1 > -1: no run of per-step distance losses, discounted at 0.99, costs more
    assert early_end_penalty(TABLE1_WEIGHTS["rough"]) == pytest.approx(-300.0)


def test_success_and_the_step_limit_are_not_penalised():
    plain, reason = _first_end(False, goal_distance_m=0.05)
    penalised, _ = _first_end(True, goal_distance_m=0.05)
    assert reason == "success" and penalised == plain
    plain, reason = _first_end(False, max_steps=3)
    penalised, _ = _first_end(True, max_steps=3)
    assert reason == "step_limit" and penalised == plain
