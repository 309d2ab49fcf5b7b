"""Environment step cost against raw physics stepping of the same world.

For each terrain, two copies of the same world are built: a `HexapodEnv` (cpg_residual mode,
a_r = 0, default observation noise: the open-loop CPG walking) and a second env of the same
config reset with the same seed, whose physics client serves as the raw world. They advance in
lockstep: every control step, `env.step` is timed on the first; then the joint targets it sent
are commanded on the second (outside the timer) and only its `substeps_per_control` calls of
`pybullet.stepSimulation` are timed. Both worlds follow the same trajectory (checked: the final
base positions must agree), so both timings cover identical physics: same contacts, same solver
work. Interleaving step by step means that load from other processes on a shared machine hits
both sides alike.

    ratio = (env time per step) / (raw stepSimulation time per control step)

The target is ratio <= 1.15. Times are CPU time of this process
(`time.process_time_ns`; PyBullet DIRECT runs in this thread); each terrain is measured
`--repeats` times and the median of each side is used.

    python bench/env_speed.py                 # all terrains, 1000 steps, 3 repeats
    python bench/env_speed.py --terrain rough --steps 500 --json out.json
    python bench/env_speed.py --breakdown     # also: where the env's time per step goes
    python bench/env_speed.py --floor         # also: the same lockstep with a bare API loop as the env

`--floor` runs the lockstep a second time with the env replaced by the least any env has to do
per control step through PyBullet's Python API: command 18 targets, the substeps, read the joint
states and the base pose into one float64 vector, cast it to float32. Its ratio is the part of
the 1.15 budget no environment code can win back on this machine under its current load (cache
contention from other processes inflates Python and API calls far more than Bullet's inner loops).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from dataclasses import dataclass

import numpy as np
import pybullet as p

from hexbench.world.env import EnvConfig, HexapodEnv

# The lowest evaluation level of each terrain (paper Table 4), where the open-loop CPG
# walks the whole way, so the robot stays in normal walking contact for the whole run.
# The terrains the 1.15 target names; the mixed (HLTA) course is composed of these.
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


def lockstep(env: HexapodEnv, raw: HexapodEnv, steps: int) -> tuple[int, int]:
    """Run `steps` control steps on both worlds; return (env CPU ns, raw stepSimulation CPU ns)."""
    env.reset(seed=SEED)
    raw.reset(seed=SEED)
    sim = raw.sim
    client, robot, joints = sim.client, sim.robot_id, sim.joint_indices
    substeps = sim.physics.substeps_per_control
    forces = [sim.robot_spec.servo_stall_torque_nm] * len(joints)
    kp = [sim.robot_spec.servo_position_gain] * len(joints)
    kd = [sim.robot_spec.servo_velocity_gain] * len(joints)
    step_simulation = p.stepSimulation
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env_ns = raw_ns = 0
    for k in range(steps):
        t0 = time.process_time_ns()
        _, _, terminated, truncated, info = env.step(action)
        env_ns += time.process_time_ns() - t0
        if terminated or truncated:
            raise RuntimeError(f"episode ended early ({info['end_reason']}) at step {k + 1}; use fewer --steps")
        p.setJointMotorControlArray(robot, joints, p.POSITION_CONTROL, targetPositions=info["a_t"].tolist(),
                                    forces=forces, positionGains=kp, velocityGains=kd, physicsClientId=client)
        t0 = time.process_time_ns()
        for _ in range(substeps):
            step_simulation(physicsClientId=client)
        raw_ns += time.process_time_ns() - t0
    env_final = env.sim.state().base_pos_m
    raw_final = np.array(p.getBasePositionAndOrientation(robot, physicsClientId=client)[0])
    gap_m = float(np.max(np.abs(env_final - raw_final)))
    if gap_m > 1e-9:
        raise RuntimeError(f"raw world diverged from the env run by {gap_m:.3g} m; "
                           "the two timings would not cover the same physics")
    return env_ns, raw_ns


def paired_runs(terrain: str, steps: int, repeats: int, run) -> list[tuple[int, int]]:
    """`repeats` calls of run(env, raw, steps) on two envs of the terrain's bench level."""
    config = EnvConfig(terrain=terrain, level=BENCH_LEVELS[terrain], action_mode="cpg_residual")
    env, raw = HexapodEnv(config), HexapodEnv(config)
    try:
        return [run(env, raw, steps) for _ in range(repeats)]
    finally:
        env.close()
        raw.close()


def measure(terrain: str, steps: int, repeats: int) -> Measurement:
    runs = paired_runs(terrain, steps, repeats, lockstep)
    return Measurement(terrain, BENCH_LEVELS[terrain], steps, statistics.median(r[0] for r in runs) / steps / 1e3,
                       statistics.median(r[1] for r in runs) / steps / 1e3)


def floor_lockstep(env: HexapodEnv, raw: HexapodEnv, steps: int) -> tuple[int, int]:
    """Like `lockstep`, with `env.step` replaced by the bare API loop (see module docstring): the joint
    targets are those the env sends (recorded in an untimed first pass), so both worlds again follow the
    env's trajectory. Returns (bare loop CPU ns, raw stepSimulation CPU ns)."""
    env.reset(seed=SEED)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    targets = []
    for k in range(steps):
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            raise RuntimeError(f"episode ended early ({info['end_reason']}) at step {k + 1}; use fewer --steps")
        targets.append(info["a_t"].tolist())
    env.reset(seed=SEED)
    raw.reset(seed=SEED)
    (client, robot, joints), (raw_client, raw_robot, raw_joints) = [
        (w.sim.client, w.sim.robot_id, w.sim.joint_indices) for w in (env, raw)]
    sim = raw.sim
    substeps = sim.physics.substeps_per_control
    forces = [sim.robot_spec.servo_stall_torque_nm] * len(joints)
    kp = [sim.robot_spec.servo_position_gain] * len(joints)
    kd = [sim.robot_spec.servo_velocity_gain] * len(joints)
    step_simulation = p.stepSimulation
    floor_ns = raw_ns = 0
    for target in targets:
        t0 = time.process_time_ns()
        p.setJointMotorControlArray(robot, joints, p.POSITION_CONTROL, targetPositions=target, forces=forces,
                                    positionGains=kp, velocityGains=kd, physicsClientId=client)
        for _ in range(substeps):
            step_simulation(physicsClientId=client)
        q, qd, _, tau = zip(*p.getJointStates(robot, joints, physicsClientId=client))
        pos, quat = p.getBasePositionAndOrientation(robot, physicsClientId=client)
        np.fromiter(q + qd + tau + pos + quat + p.getEulerFromQuaternion(quat), np.float64, 64).astype(np.float32)
        floor_ns += time.process_time_ns() - t0
        p.setJointMotorControlArray(raw_robot, raw_joints, p.POSITION_CONTROL, targetPositions=target,
                                    forces=forces, positionGains=kp, velocityGains=kd, physicsClientId=raw_client)
        t0 = time.process_time_ns()
        for _ in range(substeps):
            step_simulation(physicsClientId=raw_client)
        raw_ns += time.process_time_ns() - t0
    floor_final = np.array(p.getBasePositionAndOrientation(robot, physicsClientId=client)[0])
    raw_final = np.array(p.getBasePositionAndOrientation(raw_robot, physicsClientId=raw_client)[0])
    if float(np.max(np.abs(floor_final - raw_final))) > 1e-9:
        raise RuntimeError("bare-loop world diverged from the raw world; the two timings would not cover the same physics")
    return floor_ns, raw_ns


def measure_floor(terrain: str, steps: int, repeats: int) -> float:
    """Median floor/raw CPU time ratio (see `floor_lockstep`)."""
    runs = paired_runs(terrain, steps, repeats, floor_lockstep)
    return statistics.median(r[0] for r in runs) / statistics.median(r[1] for r in runs)


BREAKDOWN_PARTS: tuple[tuple[str, str, str], ...] = (
    # (label, object attribute path on the env, method name)
    ("CPG step", "cpg", "step"),
    ("send targets", "sim", "send_targets"),
    ("physics (stepSimulation x substeps)", "sim", "step_physics"),
    ("read state", "sim", "state"),
    ("observation", "", "_observe"),
)


def breakdown(terrain: str, steps: int) -> dict[str, float]:
    """CPU microseconds per env step spent in each part of `HexapodEnv.step` (wrapping its calls)."""
    env = HexapodEnv(EnvConfig(terrain=terrain, level=BENCH_LEVELS[terrain], action_mode="cpg_residual"))
    spent = {label: 0 for label, _, _ in BREAKDOWN_PARTS}
    try:
        env.reset(seed=SEED)
        for label, owner_name, method in BREAKDOWN_PARTS:
            owner = getattr(env, owner_name) if owner_name else env
            inner = getattr(owner, method)

            def timed(*args, _inner=inner, _label=label, **kwargs):
                t0 = time.process_time_ns()
                out = _inner(*args, **kwargs)
                spent[_label] += time.process_time_ns() - t0
                return out

            setattr(owner, method, timed)  # instance attribute shadows the method
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        t0 = time.process_time_ns()
        for _ in range(steps):
            env.step(action)
        total = time.process_time_ns() - t0
    finally:
        env.close()
    out = {label: ns / steps / 1e3 for label, ns in spent.items()}
    out["rest of step (checks, episode rules, reward, info)"] = total / steps / 1e3 - sum(out.values())
    out["total"] = total / steps / 1e3
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--terrain", action="append", choices=list(BENCH_LEVELS),
                        help="terrain to measure (repeatable; default: all)")
    parser.add_argument("--steps", type=int, default=1000, help="control steps per run (default 1000)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per terrain; medians are reported (default 3)")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON to PATH")
    parser.add_argument("--breakdown", action="store_true", help="also show where the env step's time goes")
    parser.add_argument("--floor", action="store_true",
                        help="also measure the bare PyBullet API loop's ratio: the least any env can reach here")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.repeats < 1:
        parser.error("--steps and --repeats must be at least 1")

    from rich.console import Console
    from rich.progress import track
    from rich.table import Table

    console = Console()
    terrains = args.terrain or list(BENCH_LEVELS)
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
    load = os.getloadavg()[0]
    console.print(f"worst ratio {worst.ratio:.3f} ({worst.terrain}); target <= 1.15; "
                  f"1-min load average {load:.1f} on {os.cpu_count()} CPUs (contention inflates the Python share)")
    floors = {t: measure_floor(t, args.steps, args.repeats) for t in terrains} if args.floor else {}
    if floors:
        console.print("bare API loop (floor) ratio: " + ", ".join(f"{t} {r:.3f}" for t, r in floors.items())
                      + f"; 1-min load average now {os.getloadavg()[0]:.1f}")
    parts = {t: breakdown(t, args.steps) for t in terrains} if args.breakdown else {}
    if parts:
        split = Table(title="env step breakdown, CPU us per step (a_r = 0)")
        split.add_column("part")
        for t in terrains:
            split.add_column(t, justify="right")
        for label in next(iter(parts.values())):
            split.add_row(label, *(f"{parts[t][label]:.0f}" for t in terrains))
        console.print(split)
    if args.json:
        payload = {
            "python": sys.version.split()[0], "machine": platform.machine(), "processor": platform.processor(),
            "steps": args.steps, "repeats": args.repeats, "seed": SEED, "cpus": os.cpu_count(),
            "load_average_1min": load,
            "results": [{"terrain": m.terrain, "level": m.level, "env_us_per_step": m.env_us_per_step,
                         "raw_us_per_step": m.raw_us_per_step, "ratio": m.ratio} for m in results],
            "breakdown_us_per_step": parts, "floor_ratio": floors,
        }
        with open(args.json, "w") as f:
            json.dump(payload, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
