"""Can a residual carry the CPG over the 20-deg slope crest? Hand-made residuals (issue 5, slopes).

The open-loop CPG passes slopes 18 deg and stalls at the crest of 20 deg (bench/stall_trace.py);
so does the shipped PPO-CPG, which never saw a slope steeper than its curriculum's 18 deg. This
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

    python bench/crest_residual.py [--level 20] [--episodes 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from hexbench.env import HexapodEnv
from hexbench.robot import JOINT_NAMES, LEG_NAMES
from hexbench.tasks import load_suite

BASE_X = 54  # observation index of base x [m] (hexbench.env module docstring)


def joints(kind: str) -> list[int]:
    return [JOINT_NAMES.index(f"{leg}_{kind}") for leg in LEG_NAMES]


def bias(kind: str, value: float):
    index = joints(kind)

    def residual(obs, eps):
        a = np.zeros(len(JOINT_NAMES))
        a[index] = value
        return a
    return residual


def knee_amplitude(gain: float):
    index = joints("knee")

    def residual(obs, eps):
        a = np.zeros(len(JOINT_NAMES))
        a[index] = gain * obs[index] / eps
        return a
    return residual


def gated(residual, x0_m: float, x1_m: float):
    def gated_residual(obs, eps):
        return residual(obs, eps) if x0_m <= obs[BASE_X] <= x1_m else np.zeros(len(JOINT_NAMES))
    return gated_residual


def play(residual, task, seed: int) -> tuple[str, float, int]:
    """(end reason, forward progress [m], control steps) of one protocol episode."""
    env = HexapodEnv(task.env_config("cpg_residual"))
    try:
        obs, _ = env.reset(seed=seed)
        steps, done, info = 0, False, {}
        while not done:
            action = np.clip(residual(obs, env.config.eps), -1.0, 1.0).astype(np.float32)
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
        return str(info["end_reason"]), float(info["progress_m"]), steps
    finally:
        env.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--level", type=float, default=20.0, help="slopes angle [deg], a suite level or any other")
    parser.add_argument("--episodes", type=int, default=3, help="protocol episodes per residual")
    args = parser.parse_args(argv)
    # the 20-deg task's rules (stall window, step limit, noise) at any level, seeds derived from the level
    task = dataclasses.replace(load_suite().task("slopes", 20.0), level=args.level)
    cases = [("none (open-loop CPG)", bias("knee", 0.0))]
    cases += [(f"bias {kind} a_r={v:+}", bias(kind, v)) for kind, v in
              (("knee", 0.25), ("knee", 0.5), ("ankle", -0.5))]
    cases += [("knee amplitude x1.3", knee_amplitude(0.3))]
    cases += [(f"knee amplitude x1.3, x in [{x0}, 1.3] m", gated(knee_amplitude(0.3), x0, 1.3)) for x0 in (0.75, 0.85)]
    print(f"slopes {args.level:g} deg, {args.episodes} protocol episodes each: end reason, progress [m], steps")
    for name, residual in cases:
        start = time.perf_counter()
        results = [play(residual, task, seed) for seed in task.seeds(args.episodes)]
        ends = "   ".join(f"{reason} {progress:.2f} {steps}" for reason, progress, steps in results)
        print(f"{name:38s} {ends}   ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
