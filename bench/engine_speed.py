"""The same episodes through the local process pool and through Ray.

    python bench/engine_speed.py                           # 2 workers, 2 episodes x first 2 levels per terrain
    python bench/engine_speed.py --workers 1 2 4 8 16      # scaling, where the cores exist
    python bench/engine_speed.py --episodes 4 --levels-per-terrain 3 --record

For each worker count W: `hexbench.evaluation.evaluate.evaluate` over the process pool (`workers=W`), then
over a fresh local Ray instance of W CPUs (`ray.init(num_cpus=W)`, one task per episode, started
before the clock starts; its start-up is reported apart). Both runs share one run secret, so their
rows must be identical (checked). With --repeats N each engine runs N times, alternating which
goes first, and the best time is kept. Prints wall times, the ratio Ray/pool, and, with 1 among the
worker counts, each engine's speed-up and efficiency (speed-up / workers). Worker counts above
this machine's cores are skipped (their numbers would measure oversubscription, not scaling).
Writes bench/out/engine_speed.json, with the load average: on a shared machine, say so.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from hexbench.evaluation import engines
from hexbench.evaluation.evaluate import evaluate
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


def _tasks(levels_per_terrain: int, terrains: list[str] | None):
    suite = load_suite("v1")
    chosen = []
    for terrain in terrains or suite.terrains:
        chosen += [t for t in suite.tasks if t.terrain == terrain][:levels_per_terrain]
    return chosen


def _run(controller: str, tasks, out: Path, episodes: int, workers: int, record: bool) -> tuple[float, dict]:
    t0 = time.perf_counter()
    res = evaluate(controller, tasks, out, episodes=episodes, workers=workers, record=record, progress=False,
                   command="bench/engine_speed.py")
    wall = time.perf_counter() - t0
    if res.error:
        raise SystemExit(f"error: {res.error}")
    return wall, res.record


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, nargs="+", default=[2])
    ap.add_argument("--episodes", type=int, default=2, help="episodes per level")
    ap.add_argument("--levels-per-terrain", type=int, default=2, help="the first N levels of each terrain")
    ap.add_argument("--terrain", action="append", default=None, help="repeatable; default: every terrain")
    ap.add_argument("--record", action="store_true", help="also write MCAP/.rrd (Ray ships their bytes back)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per engine, alternating which goes first; best kept")
    ap.add_argument("--controller", default=str(REPO / "baselines" / "cpg.py"))
    args = ap.parse_args()
    engines.import_ray()
    tasks = _tasks(args.levels_per_terrain, args.terrain)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    results: dict = {"cores": cores, "episodes_per_level": args.episodes, "tasks": [t.name for t in tasks],
                     "record": args.record, "runs": {}, "skipped_workers": []}
    scratch = Path(tempfile.mkdtemp(prefix="hxbench-engine-"))
    try:
        for w in args.workers:
            if w > cores:
                print(f"{w} workers: skipped ({cores} cores here)")
                results["skipped_workers"].append(w)
                continue
            pool_walls, ray_walls, ray_starts, same = [], [], [], True
            secret = None
            for repeat in range(args.repeats):
                order = ("pool", "ray") if repeat % 2 == 0 else ("ray", "pool")  # alternate: the load drifts
                for engine_name in order:
                    out = scratch / f"{engine_name}-{w}-{repeat}"
                    if secret is not None:  # one run secret for all: identical rows expected
                        (out / ".journal").mkdir(parents=True)
                        shutil.copy2(secret, out / ".journal" / "run_secret")
                    if engine_name == "pool":
                        wall, rec = _run(args.controller, tasks, out, args.episodes, w, args.record)
                        pool_walls.append(wall)
                    else:
                        t0 = time.perf_counter()
                        engine = engines.RayEngine("local", num_cpus=w,
                                                   temp_dir=tempfile.mkdtemp(prefix="hxr", dir="/tmp"))
                        engine.connect()
                        ray_starts.append(time.perf_counter() - t0)
                        try:
                            with engines.using(engine):
                                wall, rec = _run(args.controller, tasks, out, args.episodes, w, args.record)
                        finally:
                            engine.close()
                            shutil.rmtree(engine.temp_dir, ignore_errors=True)
                        ray_walls.append(wall)
                    if secret is None:
                        secret, reference = out / ".journal" / "run_secret", rec["episodes"]
                    same = same and rec["episodes"] == reference
            pool_wall, ray_wall = min(pool_walls), min(ray_walls)
            n = len(reference)
            results["runs"][str(w)] = {"workers": w, "episodes": n, "repeats": args.repeats,
                                       "pool_wall_s": pool_wall, "ray_wall_s": ray_wall,
                                       "pool_walls_s": pool_walls, "ray_walls_s": ray_walls,
                                       "ray_start_s": min(ray_starts), "ratio_ray_over_pool": ray_wall / pool_wall,
                                       "identical_rows": same}
            print(f"{w} worker(s), {n} episodes, best of {args.repeats}: pool {pool_wall:.1f} s, Ray {ray_wall:.1f} s "
                  f"(+{min(ray_starts):.1f} s to start Ray), Ray/pool {ray_wall / pool_wall:.2f}, "
                  f"rows {'identical' if same else 'DIFFER'}")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    runs = results["runs"]
    if "1" in runs:
        for key in [k for k in runs if k != "1"]:
            for engine_name in ("pool", "ray"):
                speedup = runs["1"][f"{engine_name}_wall_s"] / runs[key][f"{engine_name}_wall_s"]
                runs[key][f"{engine_name}_speedup"] = speedup
                runs[key][f"{engine_name}_efficiency"] = speedup / runs[key]["workers"]
            print(f"{key} workers: speed-up pool {runs[key]['pool_speedup']:.2f} "
                  f"(efficiency {runs[key]['pool_efficiency']:.2f}), Ray {runs[key]['ray_speedup']:.2f} "
                  f"(efficiency {runs[key]['ray_efficiency']:.2f})")
    results["load_average_at_end"] = os.getloadavg()
    print(f"load average at the end: {' '.join(f'{x:.1f}' for x in os.getloadavg())} on {cores} cores")
    out = REPO / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "engine_speed.json").write_text(json.dumps(results, indent=1))
    if not all(r["identical_rows"] for r in runs.values()):
        raise SystemExit("error: the Ray rows differ from the pool's")


if __name__ == "__main__":
    main()
