"""Full-protocol wall time of the CPG baseline with 1 and 2 workers.

    python bench/eval_speed.py                      # full protocol v1, 1 then 2 workers
    python bench/eval_speed.py --episodes 4         # 4 episodes per level (quick estimate)

Runs `hexbench.evaluation.evaluate.evaluate` without recording into fresh temporary directories and
prints wall time, episodes/s, control steps/s and the 1 -> 2 worker speed-up. Writes a JSON
summary to bench/out/eval_speed.json.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from hexbench.evaluation.evaluate import evaluate
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=None, help="episodes per level (default: protocol's 20)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--controller", default=str(REPO / "baselines" / "cpg.py"))
    args = ap.parse_args()
    tasks = load_suite("v1").tasks
    results = {}
    for w in args.workers:
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            res = evaluate(args.controller, list(tasks), Path(d) / "run", episodes=args.episodes, workers=w,
                           record=False, progress=True, command="bench/eval_speed.py")
            wall = time.perf_counter() - t0
        eps = res.record["episodes"]
        steps = sum(e["steps"] for e in eps)
        results[w] = {"workers": w, "episodes": len(eps), "wall_time_s": wall, "episodes_per_s": len(eps) / wall,
                      "control_steps_per_s": steps / wall, "control_steps": steps}
        print(f"{w} worker(s): {len(eps)} episodes, {steps} control steps in {wall:.1f} s "
              f"({len(eps) / wall:.2f} episodes/s, {steps / wall:.0f} steps/s)")
    if 1 in results and 2 in results:
        speedup = results[1]["wall_time_s"] / results[2]["wall_time_s"]
        print(f"speed-up 1 -> 2 workers: {speedup:.2f}x")
        results["speedup_1_to_2"] = speedup
    results["load_average_at_end"] = os.getloadavg()
    out = REPO / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "eval_speed.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
