"""What a 10-minute full protocol run would cost in physics fidelity.

The full protocol v1 run of the open-loop CPG simulates 27,994 s of robot time
(sum of `sim_time_s` over leaderboard/cpg.json). Ten minutes on 2 cores is 1,200 CPU-s, so a
10-minute run needs at most 1200 / 27994 = 42.9 ms of CPU per simulated second, evaluator and
controller included. This script measures, for protocol v1's physics and for cheaper candidates
(coarser physics step, fewer solver iterations, slower control), the env's CPU per simulated
second with the open-loop CPG walking (a_r = 0), and the CPG's outcomes at hard levels on the same
seeds, so a protocol v2 decision can weigh speed against changed outcomes.

    python experiments/physics_options.py                     # 4 seeds per level (a few minutes)
    python experiments/physics_options.py --seeds 6 --json physics_options.json

Projected full-protocol wall time = 27,994 s x (CPU per simulated s) / 2 cores: an ideal 2-worker
run of the physics alone (no controller, perfect scaling), so a lower bound.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, dataclass

import numpy as np

from hexbench.suite.tasks import episode_seed
from hexbench.world.env import EnvConfig, HexapodEnv
from hexbench.world.sim import PhysicsConfig

CPG_FULL_PROTOCOL_SIM_S = 27994.0  # sum of sim_time_s over leaderboard/cpg.json (protocol v1, 860 episodes)
TEN_MINUTES_CPU_S = 2 * 600.0
LEVELS: tuple[tuple[str, float], ...] = (("rough", 8.0), ("rough", 10.0), ("slopes", 15.0), ("slopes", 18.0),
                                         ("stairs", 7.5), ("stairs", 8.0))


@dataclass(frozen=True)
class Option:
    name: str
    physics_dt_s: float
    substeps_per_control: int
    solver_iterations: int

    @property
    def control_hz(self) -> float:
        return 1.0 / (self.physics_dt_s * self.substeps_per_control)


OPTIONS: tuple[Option, ...] = (
    Option("v1: 240 Hz x4, 20 it", 1 / 240, 4, 20),
    Option("240 Hz x4, 10 it", 1 / 240, 4, 10),
    Option("120 Hz x2, 20 it", 1 / 120, 2, 20),
    Option("120 Hz x2, 10 it", 1 / 120, 2, 10),
    Option("120 Hz x4, 20 it (30 Hz control)", 1 / 120, 4, 20),
)


def run_level(option: Option, terrain: str, level: float, seeds: list[int]) -> dict:
    physics = PhysicsConfig(physics_dt_s=option.physics_dt_s, substeps_per_control=option.substeps_per_control,
                            solver_iterations=option.solver_iterations)
    max_steps = round(4000 * 60.0 / option.control_hz)  # the protocol's 66.7 s at any control rate
    env = HexapodEnv(EnvConfig(terrain=terrain, level=level, stall_window_s=20.0, max_steps=max_steps, physics=physics))
    action = np.zeros(env.action_space.shape, np.float32)
    ends, sim_s, cpu_s = [], 0.0, 0.0
    for seed in seeds:
        env.reset(seed=seed)
        t0 = time.process_time()
        while True:
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        cpu_s += time.process_time() - t0
        sim_s += info["sim_time_s"]
        ends.append(info["end_reason"])
    env.close()
    return {"terrain": terrain, "level": level, "successes": ends.count("success"), "episodes": len(seeds),
            "ends": ends, "sim_s": sim_s, "cpu_s": cpu_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4, help="episodes per level (seeds from the 'physics-bench' namespace)")
    ap.add_argument("--json", default=None, help="write the results here")
    args = ap.parse_args()
    from rich.console import Console
    from rich.progress import track
    from rich.table import Table

    rows = []
    for option in track(OPTIONS, description="physics options", transient=True):
        levels = [run_level(option, t, lv, [episode_seed("physics-bench", t, lv, i) for i in range(args.seeds)])
                  for t, lv in LEVELS]
        ms_per_sim_s = 1000.0 * sum(r["cpu_s"] for r in levels) / sum(r["sim_s"] for r in levels)
        rows.append({"option": asdict(option), "control_hz": option.control_hz, "cpu_ms_per_sim_s": ms_per_sim_s,
                     "projected_full_protocol_min": CPG_FULL_PROTOCOL_SIM_S * ms_per_sim_s / 1000.0 / 2 / 60,
                     "levels": levels})
    table = Table(title=f"CPG (a_r = 0) under candidate physics, {args.seeds} seeds per level; "
                        f"10 min on 2 cores needs <= {1000 * TEN_MINUTES_CPU_S / CPG_FULL_PROTOCOL_SIM_S:.1f} ms CPU per sim s")
    table.add_column("physics")
    table.add_column("CPU ms / sim s", justify="right")
    table.add_column("full protocol, ideal 2 cores [min]", justify="right")
    for t, lv in LEVELS:
        table.add_column(f"{t} {lv:g}", justify="right")
    for row in rows:
        table.add_row(row["option"]["name"], f"{row['cpu_ms_per_sim_s']:.1f}", f"{row['projected_full_protocol_min']:.1f}",
                      *[f"{r['successes']}/{r['episodes']}" for r in row["levels"]])
    Console().print(table)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"seeds": args.seeds, "rows": rows}, f, indent=2)


if __name__ == "__main__":
    main()
