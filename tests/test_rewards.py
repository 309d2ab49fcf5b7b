"""The training reward options that price an episode's end (hexbench.training.wrappers): with
`early_end_penalty` an early end other than success never pays; with `arrival_bonus` staying near the
goal never pays more than arriving."""

import numpy as np
import pytest

from hexbench.agents.decision import DecisionInterval
from hexbench.training.wrappers import (
    ArrivalBonus,
    arrival_bonus,
    early_end_penalty,
    make_curriculum_env,
    with_end_terms,
)
from hexbench.world.env import EnvConfig, HexapodEnv
from hexbench.world.rewards import TABLE1_WEIGHTS, difficulty_factor


def _play_to_end(env, steps: int = 600) -> tuple[float, str]:
    """(the last step's reward, the end reason) of an episode of zero actions on seed 5."""
    env.reset(seed=5)
    try:
        for _ in range(steps):
            _, reward, terminated, truncated, info = env.step(np.zeros(18, np.float32))
            if terminated or truncated:
                return reward, info["end_reason"]
    finally:
        env.close()
    raise AssertionError("episode did not end")


def _first_end(penalty: bool, bonus: bool = False, **rules):
    return _play_to_end(with_end_terms(HexapodEnv(EnvConfig(terrain="rough", level=7, **rules)), penalty, bonus))


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


def test_an_arrival_earns_the_discounted_most_that_staying_near_the_goal_could():
    plain, reason = _first_end(False, goal_distance_m=0.05)
    rewarded, reason2 = _first_end(False, True, goal_distance_m=0.05)
    assert reason == reason2 == "success"
    w = TABLE1_WEIGHTS["rough"]
    expected = (1 + difficulty_factor("rough", 7)) * (w.distance * 9.0 + w.heading + w.tilt) / (1 - 0.99)
    assert rewarded - plain == pytest.approx(expected)
    assert arrival_bonus(w) == pytest.approx(2800.0)  # r_d at most 1/0.1 m - 1 = 9, r_theta and r_r at most 1
    # the other ends are not rewarded, and both options together price each end once
    for rules in ({"max_lateral_deviation_m": 0.002}, {"max_steps": 3}):
        assert _first_end(False, True, **rules)[0] == _first_end(False, **rules)[0]
    both, _ = _first_end(True, True, max_lateral_deviation_m=0.002)
    penalised, _ = _first_end(True, max_lateral_deviation_m=0.002)
    assert both == penalised
    assert isinstance(with_end_terms(HexapodEnv(EnvConfig(terrain="rough")), True, True), ArrivalBonus)


def test_per_decision_end_terms_bound_a_discount_per_decision():
    # an agent deciding every K control steps collects K steps' rewards per discount, so staying near
    # the goal is worth up to K times the per-step bound: the terms scale with K
    w = TABLE1_WEIGHTS["stairs"]
    assert arrival_bonus(w, control_steps_per_discount=30) == pytest.approx(30 * arrival_bonus(w))
    assert early_end_penalty(w, control_steps_per_discount=30) == pytest.approx(30 * early_end_penalty(w))
    staying = sum(0.99**j * 30 * (w.distance * 9.0 + w.heading + w.tilt) for j in range(10_000))
    assert arrival_bonus(w, control_steps_per_discount=30) >= staying > arrival_bonus(w)


def test_per_decision_end_terms_pay_k_times_the_bonus_on_an_arrival():
    def arrival_reward(control_steps_per_discount: int) -> float:
        env = make_curriculum_env("rough", "cpg_residual", arrival_bonus=True, goal_distance_m=0.05,
                                  control_steps_per_discount=control_steps_per_discount)
        reward, end_reason = _play_to_end(DecisionInterval(env, 30), steps=20)
        assert end_reason == "success"
        return reward

    w = TABLE1_WEIGHTS["rough"]
    delta = difficulty_factor("rough", 5.0)  # the curriculum's first level
    assert arrival_reward(30) - arrival_reward(1) == pytest.approx((1 + delta) * 29 * arrival_bonus(w))
