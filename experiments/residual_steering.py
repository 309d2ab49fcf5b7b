"""How a residual can steer the CPG's tripod gait (why PPO-CPG leaves the rough corridor).

PPO-CPG trained from scratch on rough ground fails held-out episodes by lateral deviation: its
residual a_r does not steer. This plays simple hand-made residuals on flat ground (no observation
noise, 900 control steps = 15 s) and prints the yaw turned, the forward progress and the lateral
offset at the end:

  * bias: a constant a_r on the hip joints (the same offset at every phase of the gait);
  * amplitude: a_r_hip = g * q_hip / eps on one side, q_hip the *observed* hip angle, i.e. that
    side's hip swing scaled by (1 + g): a residual that follows the gait's phase.

A steering residual of the second kind is a product of a heading signal and the gait phase: an
exploration noise that is white at 60 Hz (SB3's default Gaussian policy) averages it out over a
2 s gait cycle, while state-dependent noise held for a cycle or more (gSDE) produces it.

    python experiments/residual_steering.py [--steps 900] [--seed 1]
"""

from __future__ import annotations

import argparse

import numpy as np
from residual_episode import Residual, play_residual

from hexbench.world.env import NO_NOISE, EnvConfig
from hexbench.world.robot import JOINT_NAMES, LEG_NAMES

RIGHT_HIPS = [JOINT_NAMES.index(f"{leg}_hip") for leg in LEG_NAMES if leg.startswith("R")]
LEFT_HIPS = [JOINT_NAMES.index(f"{leg}_hip") for leg in LEG_NAMES if leg.startswith("L")]


def bias(value: float, hips: list[int]) -> Residual:
    def residual(obs, step):
        a = np.zeros(18)
        a[hips] = value
        return a
    return residual


def amplitude(gain_right: float, gain_left: float, eps: float) -> Residual:
    def residual(obs, step):
        a = np.zeros(18)
        a[RIGHT_HIPS] = gain_right * obs[RIGHT_HIPS] / eps
        a[LEFT_HIPS] = gain_left * obs[LEFT_HIPS] / eps
        return a
    return residual


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=900, help="control steps per episode (60 Hz)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    config = EnvConfig(terrain="flat", noise=NO_NOISE)
    cases = [("none (open-loop CPG)", bias(0.0, RIGHT_HIPS))]
    for v in (0.3, -0.3):
        cases += [(f"bias a_r={v:+} on all hips", bias(v, RIGHT_HIPS + LEFT_HIPS)),
                  (f"bias a_r={v:+} on right hips", bias(v, RIGHT_HIPS))]
    for g in (0.1, 0.3, -0.3):
        cases.append((f"amplitude right hips x{1 + g:.1f}", amplitude(g, 0.0, config.eps)))
    print(f"{'residual':32s} {'yaw [deg]':>10s} {'progress [m]':>13s} {'lateral [m]':>12s}")
    for name, residual in cases:
        end = play_residual(config, residual, args.seed, max_steps=args.steps)
        print(f"{name:32s} {end.yaw_turned_deg:10.1f} {end.progress_m:13.2f} {end.lateral_m:12.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
