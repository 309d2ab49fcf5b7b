"""The paper's reward (section 3.4, Table 1, eqs 7-8) for each terrain.

    R = w1 r_d + w2 r_theta + w3 r_s + w4 r_r + w5 r_h + w6 r_n,      R' = (1 + delta) R

  r_d      1/d - 1, d = distance from base to target [m] (d floored at 0.1 m: 1/d is unbounded)
  r_theta  1 - 6 theta / pi if theta <= pi/6 else 0; theta = |heading error to the target| [rad]
  r_s      -100 on the step the robot falls
  r_r      1 - |psi - psi_s| / kappa; psi = body nose-up pitch, psi_s = ground slope under the
           robot, kappa = 5 deg
  r_h      z - 12 if z > 12 cm else 0; z = base height above the start ground [cm]
  r_n      -10 on the step the 4000-step limit is exceeded

delta is the curriculum difficulty factor of eq. 8: +0.1 per 1 cm of rough height difference
above 5 cm, per 3 deg of slope above 5 deg, per 0.5 cm of step height above 5 cm (the
curriculum starting levels of section 4.1; clipped at 0 below them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class RewardWeights:
    distance: float
    heading: float
    fall: float
    tilt: float
    height: float
    step_limit: float


# Table 1 (flat ground uses the rough-terrain weights).
TABLE1_WEIGHTS: dict[str, RewardWeights] = {
    "rough": RewardWeights(3.0, 1.0, 0.1, 0.0, 0.0, 1.0),
    "slopes": RewardWeights(2.0, 0.2, 0.1, 0.01, 0.0, 1.0),
    "stairs": RewardWeights(1.0, 0.2, 0.2, 0.0, 0.01, 1.0),
}
TABLE1_WEIGHTS["flat"] = TABLE1_WEIGHTS["rough"]
TABLE1_WEIGHTS["mixed"] = TABLE1_WEIGHTS["rough"]  # the HLTA course (evaluation only)

KAPPA_DEG = 5.0
HEIGHT_THRESHOLD_CM = 12.0
MIN_DISTANCE_M = 0.1

# (base level, level step per +0.1 of delta) in the paper's units, eq. 8.
DIFFICULTY_STEP: dict[str, tuple[float, float]] = {
    "rough": (5.0, 1.0),
    "slopes": (5.0, 3.0),
    "stairs": (5.0, 0.5),
    "flat": (0.0, 1.0),
}


def difficulty_factor(terrain: str, level: float) -> float:
    """delta of eq. 8 for a terrain level in the paper's units."""
    if terrain not in ("rough", "slopes", "stairs"):
        return 0.0  # flat ground and the mixed course (evaluation only)
    base, step = DIFFICULTY_STEP[terrain]
    return max(0.0, 0.1 * (level - base) / step)


def reward_terms(*, distance_m: float, heading_error_rad: float, fell: bool, pitch_up_deg: float,
                 ground_slope_deg: float, base_height_cm: float, step_limit_exceeded: bool) -> dict[str, float]:
    """The six unweighted Table 1 terms."""
    theta = abs(heading_error_rad)
    return {
        "distance": 1.0 / max(distance_m, MIN_DISTANCE_M) - 1.0,
        "heading": 1.0 - 6.0 * theta / math.pi if theta <= math.pi / 6 else 0.0,
        "fall": -100.0 if fell else 0.0,
        "tilt": 1.0 - abs(pitch_up_deg - ground_slope_deg) / KAPPA_DEG,
        "height": base_height_cm - HEIGHT_THRESHOLD_CM if base_height_cm > HEIGHT_THRESHOLD_CM else 0.0,
        "step_limit": -10.0 if step_limit_exceeded else 0.0,
    }


def total_reward(terms: dict[str, float], weights: RewardWeights, delta: float) -> float:
    """Eq. 7 times (1 + delta) (eq. 8)."""
    r = (weights.distance * terms["distance"] + weights.heading * terms["heading"] + weights.fall * terms["fall"]
         + weights.tilt * terms["tilt"] + weights.height * terms["height"] + weights.step_limit * terms["step_limit"])
    return (1.0 + delta) * r
