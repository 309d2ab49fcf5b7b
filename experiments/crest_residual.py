"""Can a residual carry the CPG over the 20-deg slope crest? Hand-made residuals on slopes.

The open-loop CPG passes slopes 18 deg and stalls at the crest of 20 deg (experiments/stall_trace.py);
so did PPO-CPG trained on the paper's curriculum, whose top is 18 deg. This
plays simple hand-made residuals a_r on protocol episodes of one slopes level (the task's rules:
stall window, step limit, observation noise, the protocol's episode seeds) and prints how each
episode ends and how far it got:

  * bias: a constant a_r on one joint kind of every leg (the same offset at every gait phase);
  * knee amplitude x(1 + g): a_r_knee = g * q_knee / eps, q_knee the *observed* knee angle, i.e.
    every leg lifts its foot (1 + g) times as high in swing: a residual that follows the gait;
  * gated: the same, only while the observed base x lies in [x0, x1] (around the crest), which
    a policy can do since base x is in its observation.

A residual that gets over the crest says the crest is within a residual's reach; its speed says
whether the rest of the course fits in the step limit.

    python experiments/crest_residual.py [--level 20] [--episodes 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from levels import task_between
from residual_episode import Residual, play_residual

from hexbench.suite.tasks import load_suite
from hexbench.world.robot import JOINT_NAMES, LEG_NAMES

BASE_X = 54  # observation index of base x [m] (hexbench.world.env module docstring)


def joints(kind: str) -> list[int]:
    return [JOINT_NAMES.index(f"{leg}_{kind}") for leg in LEG_NAMES]


def bias(kind: str, value: float) -> Residual:
    index = joints(kind)

    def residual(obs, step):
        a = np.zeros(len(JOINT_NAMES))
        a[index] = value
        return a
    return residual


def knee_amplitude(gain: float, eps: float) -> Residual:
    index = joints("knee")

    def residual(obs, step):
        a = np.zeros(len(JOINT_NAMES))
        a[index] = gain * obs[index] / eps
        return a
    return residual


def gated(residual: Residual, x0_m: float, x1_m: float) -> Residual:
    def gated_residual(obs, step):
        return residual(obs, step) if x0_m <= obs[BASE_X] <= x1_m else np.zeros(len(JOINT_NAMES))
    return gated_residual


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--level", type=float, default=20.0, help="slopes angle [deg], a suite level or any below the top")
    parser.add_argument("--episodes", type=int, default=3, help="protocol episodes per residual")
    args = parser.parse_args(argv)
    try:  # a level between suite levels: the next suite level's rules, seeds derived from the level
        task = task_between(load_suite(), "slopes", args.level)
    except ValueError as e:
        raise SystemExit(f"error: {e}") from None
    config = task.env_config("cpg_residual")
    cases = [("none (open-loop CPG)", bias("knee", 0.0))]
    cases += [(f"bias {kind} a_r={v:+}", bias(kind, v)) for kind, v in
              (("knee", 0.25), ("knee", 0.5), ("ankle", -0.5))]
    cases += [("knee amplitude x1.3", knee_amplitude(0.3, config.eps))]
    cases += [(f"knee amplitude x1.3, x in [{x0}, 1.3] m", gated(knee_amplitude(0.3, config.eps), x0, 1.3)) for x0 in (0.75, 0.85)]
    print(f"slopes {args.level:g} deg, {args.episodes} protocol episodes each: end reason, progress [m], steps")
    for name, residual in cases:
        start = time.perf_counter()
        ends = "   ".join(f"{end.end_reason} {end.progress_m:.2f} {end.steps}"
                           for end in (play_residual(config, residual, seed) for seed in task.seeds(args.episodes)))
        print(f"{name:38s} {ends}   ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
