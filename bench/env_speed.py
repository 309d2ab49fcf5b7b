"""Environment step cost against raw physics stepping of the same world (issue 2).

For each terrain, one `HexapodEnv` (cpg_residual mode, a_r = 0, default observation noise:
the open-loop CPG walking) is reset with a fixed seed and stepped `--steps` times, timing
every `env.step`. Then the *same* world is rebuilt (`reset` with the same seed gives the same
terrain instance and start pose) and the joint targets the env actually sent are replayed,
timing only the `substeps_per_control` calls of `pybullet.stepSimulation` per control step
(the motor command that moves the robot is issued outside the timer). The replay follows the
same trajectory as the env run (checked: the final base positions must agree), so both
timings cover identical physics: same contacts, same solver work.

    ratio = (env time per step) / (raw stepSimulation time per control step)

The issue's target is ratio <= 1.15. Times are CPU time of this process
(`time.process_time_ns`; PyBullet DIRECT runs in this thread), so other processes on a
shared machine do not inflate them; each terrain is measured `--repeats` times, alternating
env and raw, and the median of each is used.

    python bench/env_speed.py                 # all terrains, 1000 steps, 3 repeats
    python bench/env_speed.py --terrain rough --steps 500 --json out.json
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from dataclasses import dataclass

import numpy as np
import pybullet as p

from hexbench.env import EnvConfig, HexapodEnv
from hexbench.terrain import TERRAIN_KINDS

# The lowest evaluation level of each terrain (paper Table 4), where the open-loop CPG
# walks the whole way, so the robot stays in normal walking contact for the whole run.
BENCH_LEVELS: dict[str, float] = {"flat": 0.0, "rough": 3.0, "slopes": 6.0, "stairs": 2.0}
SEED = 12345


@dataclass
class Measurement:
    terrain: str
    level: float
    steps: int
    env_us_per_step: float
    raw_us_per_step: float

    @property
    def ratio(self) -> float:
        return self.env_us_per_step / self.raw_us_per_step

    @property
    def env_steps_per_s(self) -> float:
        return 1e6 / self.env_us_per_step

    @property
    def raw_steps_per_s(self) -> float:
        return 1e6 / self.raw_us_per_step


def time_env(env: HexapodEnv, steps: int) -> tuple[int, list[np.ndarray], np.ndarray]:
    """Step the env with a_r = 0; return (CPU ns, joint targets sent per step, final base xyz)."""
    env.reset(seed=SEED)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    sent: list[np.ndarray] = []
    total_ns = 0
    for _ in range(steps):
        t0 = time.process_time_ns()
        _, _, terminated, truncated, info = env.step(action)
        total_ns += time.process_time_ns() - t0
        sent.append(np.array(info["a_t"]))
        if terminated or truncated:
            raise RuntimeError(f"episode ended early ({info['end_reason']}) at step {len(sent)}; use fewer --steps")
    return total_ns, sent, env.sim.state().base_pos_m


def time_raw(env: HexapodEnv, targets: list[np.ndarray]) -> tuple[int, np.ndarray]:
    """Rebuild the same world and replay `targets`, timing only stepSimulation; (CPU ns, final base xyz)."""
    env.reset(seed=SEED)
    sim = env.sim
    client, robot = sim.client, sim.robot_id
    substeps = sim.physics.substeps_per_control
    forces = [sim.robot_spec.servo_stall_torque_nm] * len(sim.joint_indices)
    kp = [sim.robot_spec.servo_position_gain] * len(sim.joint_indices)
    kd = [sim.robot_spec.servo_velocity_gain] * len(sim.joint_indices)
    step_simulation = p.stepSimulation
    total_ns = 0
    for target in targets:
        p.setJointMotorControlArray(robot, sim.joint_indices, p.POSITION_CONTROL, targetPositions=target.tolist(),
                                    forces=forces, positionGains=kp, velocityGains=kd, physicsClientId=client)
        t0 = time.process_time_ns()
        for _ in range(substeps):
            step_simulation(physicsClientId=client)
        total_ns += time.process_time_ns() - t0
    pos, _ = p.getBasePositionAndOrientation(robot, physicsClientId=client)
    return total_ns, np.array(pos)


def measure(terrain: str, steps: int, repeats: int) -> Measurement:
    level = BENCH_LEVELS[terrain]
    env = HexapodEnv(EnvConfig(terrain=terrain, level=level, action_mode="cpg_residual"))
    try:
        env_ns, raw_ns = [], []
        for _ in range(repeats):
            e_ns, targets, env_final = time_env(env, steps)
            r_ns, raw_final = time_raw(env, targets)
            gap_m = float(np.max(np.abs(env_final - raw_final)))
            if gap_m > 1e-6:
                raise RuntimeError(f"{terrain}: raw replay diverged from the env run by {gap_m:.3g} m; "
                                   "the two timings would not cover the same physics")
            env_ns.append(e_ns)
            raw_ns.append(r_ns)
    finally:
        env.close()
    return Measurement(terrain, level, steps, statistics.median(env_ns) / steps / 1e3,
                       statistics.median(raw_ns) / steps / 1e3)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--terrain", action="append", choices=TERRAIN_KINDS,
                        help="terrain to measure (repeatable; default: all)")
    parser.add_argument("--steps", type=int, default=1000, help="control steps per run (default 1000)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per terrain; medians are reported (default 3)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON to PATH")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.repeats < 1:
        parser.error("--steps and --repeats must be at least 1")

    from rich.console import Console
    from rich.progress import track
    from rich.table import Table

    console = Console()
    terrains = args.terrain or list(TERRAIN_KINDS)
    results = [measure(t, args.steps, args.repeats)
               for t in track(terrains, description="measuring", console=console, transient=True)]

    env_cfg = EnvConfig(terrain="flat")
    table = Table(title=f"env step vs raw stepSimulation ({env_cfg.physics.substeps_per_control} substeps of "
                        f"{env_cfg.physics.physics_dt_s * 1e3:.3f} ms per control step, CPU time, "
                        f"median of {args.repeats} x {args.steps} steps)")
    for col in ("terrain", "level", "env steps/s", "raw steps/s", "env us/step", "raw us/step", "ratio"):
        table.add_column(col, justify="right" if col != "terrain" else "left")
    for m in results:
        table.add_row(m.terrain, f"{m.level:g}", f"{m.env_steps_per_s:.0f}", f"{m.raw_steps_per_s:.0f}",
                      f"{m.env_us_per_step:.0f}", f"{m.raw_us_per_step:.0f}", f"{m.ratio:.3f}")
    console.print(table)
    worst = max(results, key=lambda m: m.ratio)
    console.print(f"worst ratio {worst.ratio:.3f} ({worst.terrain}); target <= 1.15")
    if args.json:
        payload = {
            "python": sys.version.split()[0], "machine": platform.machine(), "processor": platform.processor(),
            "steps": args.steps, "repeats": args.repeats, "seed": SEED,
            "results": [{"terrain": m.terrain, "level": m.level, "env_us_per_step": m.env_us_per_step,
                         "raw_us_per_step": m.raw_us_per_step, "ratio": m.ratio} for m in results],
        }
        with open(args.json, "w") as f:
            json.dump(payload, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
