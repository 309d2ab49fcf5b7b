"""What the waiting budget counts for honest controllers (hexbench.evaluation.isolation.Limits.wait_budget_s).

    python bench/controller_waiting.py                                    # CPG and PPO-CPG, rough 3 cm, 2 episodes
    python bench/controller_waiting.py --controllers baselines/hlta.py --terrain stairs --level 8

Plays episodes with each controller sandboxed (the default isolation) in one pinned worker, as
`hexbench run` does, and reports per controller: its calls, their wall time, the time the controller
ran or was queued for a CPU (with the evaluator's queued time: the busy time the rule measures
against), the raw waiting per call (wall time less busy time, negative when busy time exceeds the
calls' wall time, as it does when the evaluator waits for a core between calls), and the waiting
the rule counted against the 60 s budget. An honest controller should count 0 s.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hexbench.evaluation import sandbox
from hexbench.evaluation.workers import pin_to_core
from hexbench.suite.numerics import use_controller_math
from hexbench.suite.rollout import play
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


def measure(controller: str, terrain: str, level: float, episodes: int) -> dict:
    """Play `episodes` episodes with `controller` sandboxed; the totals of every count of calls."""
    totals = {"calls": 0, "wall_s": 0.0, "busy_s": 0.0}
    count_waiting = sandbox.ControllerProcess._count_waiting

    def counting(process, what, context):  # the same count, with its inputs added up on the way
        busy_before = process._count_busy_s
        totals["calls"] += process._count_calls
        totals["wall_s"] += process._count_wall_s
        try:
            count_waiting(process, what, context)
        finally:
            totals["busy_s"] += process._count_busy_s - busy_before

    task = load_suite("v1").task(terrain, level)
    sandbox.ControllerProcess._count_waiting = counting
    try:
        ctrl = sandbox.controller_for(controller, task, sandbox.resolve_isolation("auto"))
        t0 = time.perf_counter()
        steps = sum(play(task, seed, ctrl, controller_seed=5).row["steps"] for seed in task.seeds(episodes))
        totals["elapsed_s"] = time.perf_counter() - t0
        totals["steps"] = steps
        totals["counted_s"] = ctrl.process._waited_s
    finally:
        sandbox.ControllerProcess._count_waiting = count_waiting
        sandbox.close_all()
    return totals


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--controllers", nargs="+", default=[str(REPO / "baselines" / f) for f in ("cpg.py", "ppo_cpg.py")])
    ap.add_argument("--terrain", default="rough")
    ap.add_argument("--level", type=float, default=3.0)
    ap.add_argument("--episodes", type=int, default=2)
    args = ap.parse_args()
    if not sandbox.SCHEDULER_COUNTERS:
        raise SystemExit("this kernel keeps no per-thread scheduler counters: waiting is not counted here")
    use_controller_math()
    pin_to_core()
    for controller in args.controllers:
        t = measure(controller, args.terrain, args.level, args.episodes)
        raw_us = (t["wall_s"] - t["busy_s"]) / max(1, t["calls"]) * 1e6
        print(f"{Path(controller).name}: {args.terrain} {args.level:g}, {args.episodes} episodes, {t['steps']} steps in "
              f"{t['elapsed_s']:.1f} s; {t['calls']} calls counted, {t['wall_s']:.2f} s of wall time in them, busy "
              f"{t['busy_s']:.2f} s; raw waiting {raw_us:+.0f} us per call; counted against the budget: {t['counted_s']:.3f} s",
              flush=True)


if __name__ == "__main__":
    main()
