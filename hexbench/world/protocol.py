"""The episode rules: when an episode ends, and whether it counts as a success.

Checked after every control step, in this order (the first that holds ends the episode):
  fall               the body is tilted more than `fall_tilt_deg` from upright (its up axis makes
                     an angle > fall_tilt_deg with world up), wherever the robot is;
  lateral_deviation  |y - y_start| > max_lateral_deviation_m (exactly 0.8 m is still allowed);
  success            x - x_start >= goal_distance_m (exactly 2.5 m counts);
  stalled            (if enabled) x advanced less than stall_min_progress_m over the last
                     stall_window_s of simulated time;
  step_limit         max_steps control steps were taken (truncation, not termination).
A fall or a lateral deviation on the step the goal line is crossed is therefore a failure.
Only `success` is a success.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class EpisodeRules:
    goal_distance_m: float = 2.5
    max_lateral_deviation_m: float = 0.8
    fall_tilt_deg: float = 60.0
    max_steps: int = 4000
    stall_window_steps: int | None = None
    stall_min_progress_m: float = 0.05

    @property
    def min_up_z(self) -> float:
        """cos(fall_tilt): the body's up axis z component below which the robot has fallen."""
        return math.cos(math.radians(self.fall_tilt_deg))


class EpisodeJudge:
    """Applies `EpisodeRules` step by step to one episode's trajectory."""

    def __init__(self, rules: EpisodeRules):
        self.rules = rules
        self._min_up_z = rules.min_up_z  # once, not every step
        self._x_history: list[float] = []

    def reset(self) -> None:
        self._x_history = []

    def end_reason(self, *, step: int, progress_m: float, lateral_m: float, up_z: float) -> str | None:
        """The reason the episode ends after control step `step` (1-based), or None to go on."""
        r = self.rules
        if up_z < self._min_up_z:
            return "fall"
        if abs(lateral_m) > r.max_lateral_deviation_m:
            return "lateral_deviation"
        if progress_m >= r.goal_distance_m:
            return "success"
        if r.stall_window_steps:
            self._x_history.append(progress_m)
            if len(self._x_history) > r.stall_window_steps:
                if progress_m - self._x_history[0] < r.stall_min_progress_m:
                    return "stalled"
                self._x_history.pop(0)
        if step >= r.max_steps:
            return "step_limit"
        return None
