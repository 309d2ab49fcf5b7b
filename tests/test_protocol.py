"""The episode rules on synthetic trajectories (no physics)."""

import pytest

from hexbench.world.protocol import EpisodeJudge, EpisodeRules

UPRIGHT = 1.0


def judge(**rules) -> EpisodeJudge:
    return EpisodeJudge(EpisodeRules(**rules))


def run(j: EpisodeJudge, trajectory):
    """trajectory: [(progress_m, lateral_m, up_z)]; returns (end step, reason)."""
    j.reset()
    for step, (x, y, up) in enumerate(trajectory, start=1):
        reason = j.end_reason(step=step, progress_m=x, lateral_m=y, up_z=up)
        if reason:
            return step, reason
    return None, None


def test_exactly_goal_distance_is_success():
    assert run(judge(), [(1.0, 0.0, UPRIGHT), (2.5, 0.0, UPRIGHT)]) == (2, "success")


def test_just_short_of_goal_is_not_success():
    assert run(judge(), [(2.4999, 0.0, UPRIGHT)]) == (None, None)


@pytest.mark.parametrize("y", [0.8, -0.8])
def test_lateral_exactly_limit_still_allowed(y):
    assert run(judge(), [(1.0, y, UPRIGHT), (2.5, y, UPRIGHT)]) == (2, "success")


def test_lateral_beyond_limit_fails_even_at_goal_line():
    assert run(judge(), [(1.0, 0.5, UPRIGHT), (2.6, 0.8001, UPRIGHT)]) == (2, "lateral_deviation")


def test_fall_at_goal_line_is_a_fall_not_a_success():
    fallen = 0.3  # up axis 72.5 deg from vertical
    assert run(judge(), [(2.0, 0.0, UPRIGHT), (2.5, 0.0, fallen)]) == (2, "fall")


def test_tilt_just_under_threshold_is_not_a_fall():
    import math

    up = math.cos(math.radians(59.9))
    assert run(judge(), [(0.1, 0.0, up)]) == (None, None)


def test_step_limit_truncates():
    assert run(judge(max_steps=3), [(0.1 * k, 0.0, UPRIGHT) for k in range(10)]) == (3, "step_limit")


def test_stall_rule_needs_a_full_window_of_no_progress():
    rules = dict(stall_window_steps=5, stall_min_progress_m=0.05)
    moving = [(0.02 * k, 0.0, UPRIGHT) for k in range(20)]  # 0.1 m per window
    assert run(judge(**rules), moving) == (None, None)
    stuck = [(0.3, 0.0, UPRIGHT)] * 20
    assert run(judge(**rules), stuck) == (6, "stalled")
