"""Measure the simulated JetHexa's physical figures quoted in docs/robot.md.

    python experiments/robot_facts.py            # prints a table; --json PATH also writes them

Measured in PyBullet with the default `JetHexaSpec` and `PhysicsConfig`:
  - total mass (sum over all links as PyBullet loaded them);
  - standing heights after 2 s on flat ground at zero joint targets: body centre and whole-robot
    centre of mass (paper Table 3: centre of mass 12 cm);
  - overall footprint at the all-zero stance, feet included (paper Table 3: 39.7 x 42.6 cm);
  - servo limits in action: the largest joint torque while the legs push at their limit (body
    held 4 cm low), and joint speeds, both instantaneous (per physics step) and averaged over a
    control period, while every joint is driven across its range in the air;
  - reset cost and memory growth over 200 resets per terrain.
"""

from __future__ import annotations

import argparse
import gc
import json
import tempfile
import time
from functools import lru_cache

import numpy as np
import psutil
import pybullet as p

from hexbench.world.env import EnvConfig, HexapodEnv
from hexbench.world.robot import NUM_JOINTS, JetHexaSpec, urdf_text
from hexbench.world.sim import PhysicsConfig, Simulation
from hexbench.world.terrain import FlatTerrain

SPEC = JetHexaSpec()


@lru_cache(maxsize=1)
def urdf_file() -> str:
    """The robot's URDF (`urdf_text(SPEC)`) in a temporary file: PyBullet loads URDF from files only."""
    with tempfile.NamedTemporaryFile("w", prefix="jethexa_", suffix=".urdf", delete=False) as f:
        f.write(urdf_text(SPEC))
    return f.name


def link_masses(client: int, robot: int) -> list[float]:
    return [p.getDynamicsInfo(robot, link, physicsClientId=client)[0] for link in range(-1, NUM_JOINTS)]


def standing() -> dict[str, float]:
    sim = Simulation()
    try:
        sim.load(FlatTerrain(), np.random.default_rng(0))
        c, r = sim.client, sim.robot_id
        mass = sum(link_masses(c, r))
        for _ in range(120):  # 2 s
            sim.send_targets(np.zeros(NUM_JOINTS))
            sim.step_physics()
        com = np.zeros(3)
        for link, m in zip(range(-1, NUM_JOINTS), link_masses(c, r)):
            pos = (p.getBasePositionAndOrientation(r, physicsClientId=c)[0] if link < 0
                   else p.getLinkState(r, link, computeForwardKinematics=True, physicsClientId=c)[0])
            com += m * np.array(pos)
        state = sim.state()
        return {"total_mass_kg": mass, "standing_body_centre_height_m": float(state.base_pos_m[2]),
                "standing_com_height_m": float(com[2] / mass),
                "standing_max_joint_torque_nm": float(np.abs(state.joint_torque_nm).max())}
    finally:
        sim.close()


def footprint() -> dict[str, float]:
    c = p.connect(p.DIRECT)
    try:
        r = p.loadURDF(urdf_file(), [0, 0, 1], useFixedBase=True, physicsClientId=c)
        feet = []
        for leg in range(6):
            s = p.getLinkState(r, 3 * leg + 2, computeForwardKinematics=True, physicsClientId=c)
            rot = np.array(p.getMatrixFromQuaternion(s[5])).reshape(3, 3)
            feet.append(np.array(s[4]) + rot @ [0, 0, -(SPEC.tibia_length_m - SPEC.foot_radius_m)])
        feet = np.array(feet)
        r_m = SPEC.foot_radius_m
        return {"footprint_length_m": float(np.ptp(feet[:, 0]) + 2 * r_m),
                "footprint_width_m": float(np.ptp(feet[:, 1]) + 2 * r_m)}
    finally:
        p.disconnect(c)


def servo_limits() -> dict[str, float]:
    out: dict[str, float] = {}
    sim = Simulation()
    try:  # stall: body held 4 cm below its stance, legs pushing down
        sim.load(FlatTerrain(), np.random.default_rng(0))
        c, r = sim.client, sim.robot_id
        p.createConstraint(r, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0], [0, 0, 0.08], physicsClientId=c)
        peak = 0.0
        for _ in range(60):
            sim.send_targets(np.tile([0.0, -0.8, 0.8], 6))
            sim.step_physics()
            peak = max(peak, float(np.abs(sim.state().joint_torque_nm).max()))
        out["pushing_max_joint_torque_nm"] = peak
    finally:
        sim.close()
    sim = Simulation()
    try:  # speed: fixed base in the air, every joint driven end to end
        sim.load(FlatTerrain(), np.random.default_rng(0))
        c = sim.client
        p.removeBody(sim.robot_id, physicsClientId=c)
        sim.robot_id = r = p.loadURDF(urdf_file(), [0, 0, 1.0], useFixedBase=True, physicsClientId=c)
        inst, avg = 0.0, 0.0
        dt = PhysicsConfig().control_dt_s
        prev = sim.state().joint_pos_rad
        for target in (np.tile([0.8, 1.5, -1.5], 6), np.tile([-0.8, -0.8, 0.8], 6)):
            for _ in range(60):
                sim.send_targets(target)
                for _ in range(sim.physics.substeps_per_control):
                    p.stepSimulation(physicsClientId=c)
                    vel = [s[1] for s in p.getJointStates(r, sim.joint_indices, physicsClientId=c)]
                    inst = max(inst, float(np.abs(vel).max()))
                pos = sim.state().joint_pos_rad
                avg = max(avg, float(np.abs(pos - prev).max() / dt))
                prev = pos
        out["air_max_instantaneous_joint_speed_rad_per_s"] = inst
        out["air_max_control_period_joint_speed_rad_per_s"] = avg
    finally:
        sim.close()
    return out


def resets(n: int = 200) -> dict[str, float]:
    out: dict[str, float] = {}
    for terrain, level in (("flat", 0.0), ("rough", 12.0), ("slopes", 15.0), ("stairs", 8.0)):
        env = HexapodEnv(EnvConfig(terrain=terrain, level=level))
        try:
            for k in range(10):
                env.reset(seed=k)
            gc.collect()
            rss0 = psutil.Process().memory_info().rss
            t0 = time.process_time()
            for k in range(n):
                env.reset(seed=100 + k)
            cpu = time.process_time() - t0
            gc.collect()
            out[f"{terrain}_reset_cpu_ms"] = 1e3 * cpu / n
            out[f"{terrain}_{n}_resets_rss_growth_mb"] = (psutil.Process().memory_info().rss - rss0) / 2**20
        finally:
            env.close()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", metavar="PATH", help="also write the figures as JSON")
    args = parser.parse_args()
    from rich.console import Console
    from rich.table import Table

    console = Console()
    figures: dict[str, float] = {}
    for name, fn in (("standing", standing), ("footprint", footprint), ("servos", servo_limits), ("resets", resets)):
        with console.status(f"measuring {name}"):
            figures.update(fn())
    table = Table(title="simulated JetHexa, measured")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for key, value in figures.items():
        table.add_row(key, f"{value:.4g}")
    console.print(table)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
