"""How much of a full protocol run the physics alone takes: every level of protocol v1, the
controller in-process, PyBullet's stepping timed apart from the rest of each control step.

    python bench/protocol_physics.py                  # both cores at once, one process each (as `hexbench run` loads them)
    python bench/protocol_physics.py --cores 1        # one process; the other core left idle
    python bench/protocol_physics.py --episodes 2 --controller baselines/cpg.py

Each process (pinned to a core of its own) plays episode 0 (to `--episodes`) of all 43 levels,
the controller in-process with an evaluation worker's math, through the one episode loop
(`hexbench.suite.rollout.play`), and times `Simulation.step_physics` (the substeps of
`pybullet.stepSimulation`) and each whole episode. Per level, physics [us] per control step times
that level's control steps in the controller's committed record (leaderboard/<name>.json: 20
episodes per level) gives the physics of the full protocol [core-seconds]; half of it is the
wall time of the physics alone on two cores used perfectly, against the 10 minutes a full run
may take. The episodes played must equal the record's rows (steps and outcome). Writes
bench/out/protocol_physics.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from sandbox_overhead import StepTimer

from hexbench.evaluation import sandbox
from hexbench.evaluation.workers import pin_to_core
from hexbench.suite import rollout
from hexbench.suite.numerics import use_controller_math
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


def play_levels(controller: str, episodes: int, slot: int) -> list[dict]:
    """In this process, pinned to core `slot`: per episode, its level, steps, outcome, physics and
    whole-episode wall time [s]."""
    pin_to_core(slot)
    use_controller_math()
    out = []
    for task in load_suite("v1").tasks:
        ctrl = sandbox.controller_for(controller, task, "none")
        for index, seed in enumerate(task.seeds(episodes)):
            env = rollout.make_env(task, ctrl.action_mode)
            timer = StepTimer()
            env.sim.step_physics = timer.wrap("physics", env.sim.step_physics)
            t0 = time.perf_counter()
            row = rollout.play(task, seed, ctrl, index=index, controller_seed=5, env=env).row
            wall = time.perf_counter() - t0
            env.close()
            out.append({"terrain": task.terrain, "level": task.level, "index": index, "steps": row["steps"],
                        "end_reason": row["end_reason"], "physics_s": timer.sums["physics"], "episode_s": wall})
    sandbox.close_all()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--controller", default=str(REPO / "baselines" / "ppo_cpg.py"))
    ap.add_argument("--episodes", type=int, default=1, help="episodes per level, from index 0")
    ap.add_argument("--cores", type=int, default=2, help="processes at once, one per core")
    args = ap.parse_args()
    record_file = REPO / "leaderboard" / f"{Path(args.controller).stem}.json"
    if not record_file.is_file():  # its rows give each level's control steps over the full protocol
        raise SystemExit(f"{record_file.relative_to(REPO)} not found: --controller must be a baseline with a "
                         f"committed record ({', '.join(sorted(f.stem for f in record_file.parent.glob('*.json')))})")
    record = json.loads(record_file.read_text())
    steps_per_level: dict[tuple, int] = defaultdict(int)
    rows = {}
    for r in record["episodes"]:
        steps_per_level[r["terrain"], r["level"]] += r["steps"]
        rows[r["terrain"], r["level"], r["index"]] = (r["steps"], r["end_reason"])
    with ProcessPoolExecutor(max_workers=args.cores, mp_context=get_context("spawn")) as pool:
        results = list(pool.map(play_levels, [args.controller] * args.cores, [args.episodes] * args.cores,
                                range(args.cores)))
    summary = []
    for core, episodes in enumerate(results):
        same = sum(rows.get((e["terrain"], e["level"], e["index"])) == (e["steps"], e["end_reason"]) for e in episodes)
        by_level: dict[tuple, list] = defaultdict(lambda: [0.0, 0.0, 0])
        for e in episodes:
            acc = by_level[e["terrain"], e["level"]]
            acc[0] += e["physics_s"]
            acc[1] += e["episode_s"]
            acc[2] += e["steps"]
        physics_core_s = sum(p / n * steps_per_level[key] for key, (p, _, n) in by_level.items())
        episode_core_s = sum(w / n * steps_per_level[key] for key, (_, w, n) in by_level.items())
        steps = sum(e["steps"] for e in episodes)
        line = {"core_slot": core, "episodes": len(episodes), "equal_to_record": same, "control_steps": steps,
                "physics_us_per_step": sum(e["physics_s"] for e in episodes) / steps * 1e6,
                "episode_us_per_step": sum(e["episode_s"] for e in episodes) / steps * 1e6,
                "full_protocol_physics_core_s": physics_core_s, "full_protocol_episodes_core_s": episode_core_s}
        summary.append(line)
        print(f"core slot {core}: {len(episodes)} episodes ({same} equal to {record_file.name}), {steps:,} control steps; "
              f"physics {line['physics_us_per_step']:.0f} us of {line['episode_us_per_step']:.0f} us per control step "
              f"({line['physics_us_per_step'] / line['episode_us_per_step']:.0%}); over the full protocol "
              f"({sum(steps_per_level.values()):,} control steps) the physics alone is {physics_core_s:,.0f} core-s, "
              f"{physics_core_s / 2 / 60:.1f} min on 2 cores used perfectly (the whole in-process episodes: "
              f"{episode_core_s / 2 / 60:.1f} min)", flush=True)
    physics_min = statistics.mean(s["full_protocol_physics_core_s"] for s in summary) / 2 / 60
    print(f"physics alone of the full protocol: {physics_min:.1f} min of 2 cores ({args.cores} core(s) busy while measured)")
    out = REPO / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "protocol_physics.json").write_text(json.dumps({
        "controller": args.controller, "episodes_per_level": args.episodes, "cores_busy": args.cores,
        "full_protocol_control_steps": sum(steps_per_level.values()), "per_core": summary,
        "physics_alone_min_on_2_cores": physics_min, "load_average_at_end": os.getloadavg()}, indent=1))


if __name__ == "__main__":
    main()
