"""What episode recording costs: evaluation time with and without recording, and bytes per episode.

The open-loop CPG baseline (baselines/cpg.py) is evaluated with `hexbench.evaluation.evaluate.evaluate`
on a task selection twice per repeat, once with `record=False` and once with `record=True`
(alternating, in this process: workers = 1), and

    time ratio = (evaluation time with recording) / (evaluation time without)

is reported from the medians over the repeats (which configuration runs first alternates), both
as CPU time of this process (`time.process_time`, which also counts Rerun's writer threads) and
as wall time. On a busy
shared machine both ratios move by +-10% between runs of identical work, so the recorder's own
CPU time is also measured directly (each on_reset / on_step / on_end call timed) and reported
as a fraction of the unrecorded evaluation's CPU time: the steadier figure.
Bytes per episode (.mcap, .rrd, both) come from the recorded run's files. The worst case for
size is an episode that runs to the step limit (4000 steps): the bench also drives the recorder
directly for `--long-steps` steps on rough 6 cm with the goal moved out of reach (and no
lateral-deviation or fall end), once with the open-loop CPG (zero residual) and once with a
white-noise residual (sigma 0.3, a pessimistic stand-in for a learned policy: noisy actions
compress worst), and reports those files' bytes. The targets are a time ratio <= 1.05
and <= 1 MB per episode for both files together.

    python bench/record_overhead.py                              # one level per terrain, 2 episodes each
    python bench/record_overhead.py --full --repeats 1           # the whole protocol v1 (long)
    python bench/record_overhead.py --terrain stairs --levels 2 --episodes 3 --json out.json
    perf stat -e task-clock python bench/record_overhead.py --one-process record   # (or plain, none)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
CPG = REPO / "baselines" / "cpg.py"
DEFAULT_LEVELS = {"rough": 6.0, "slopes": 10.0, "stairs": 5.0}  # mid paper levels the CPG mostly walks


class _TimedRecorder:
    """Wraps a recorder and adds the time spent in its calls to a shared counter."""

    def __init__(self, inner, clock: dict):
        self._inner, self._clock = inner, clock

    def _timed(self, name, *args):
        t0 = time.process_time()  # CPU time of the process: includes Rerun's writer threads
        try:
            return getattr(self._inner, name)(*args)
        finally:
            self._clock["recorder_s"] += time.process_time() - t0

    def on_reset(self, env):
        return self._timed("on_reset", env)

    def on_step(self, env, obs, action, reward, info):
        return self._timed("on_step", env, obs, action, reward, info)

    def on_end(self, row):
        return self._timed("on_end", row)

    def abort(self):
        return self._inner.abort()


def _run(tasks, episodes: int | None, record: bool, clock: dict) -> dict:
    from hexbench.evaluation.evaluate import evaluate

    with tempfile.TemporaryDirectory(prefix="hexbench_bench_") as tmp:
        out = Path(tmp) / "run"
        wall0, cpu0 = time.perf_counter(), time.process_time()
        result = evaluate(str(CPG), tasks, out, episodes=episodes, workers=1, record=record, progress=False)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        if result.error:
            raise SystemExit(f"error: {result.error}")
        sizes = []
        if record:
            for mcap in sorted((out / "episodes").glob("*.mcap")):
                rrd = mcap.with_suffix(".rrd")
                sizes.append({"episode": mcap.stem, "mcap_bytes": mcap.stat().st_size, "rrd_bytes": rrd.stat().st_size})
        steps = {f"{e['terrain']}-{e['level']:g}-{e['index']:02d}": e["steps"] for e in result.record["episodes"]}
    return {"wall_s": wall, "cpu_s": cpu, "sizes": sizes, "steps": steps}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--terrain", action="append", choices=sorted(DEFAULT_LEVELS), help="terrain (repeatable)")
    ap.add_argument("--levels", help="comma-separated levels (default: one mid level per terrain)")
    ap.add_argument("--episodes", type=int, default=2, help="episodes per level (default 2)")
    ap.add_argument("--full", action="store_true", help="the whole protocol v1 (all levels, 20 episodes each)")
    ap.add_argument("--repeats", type=int, default=2, help="runs of each configuration (default 2)")
    ap.add_argument("--long-steps", type=int, default=4000,
                    help="also record episodes of this many steps for their size (default 4000, 0: skip)")
    ap.add_argument("--paired", type=int, default=0,
                    help="also run this many pairs of one episode (stairs 5 cm, index 0) with and without recording, "
                         "back to back in alternating order, and report the median of the pairs' CPU ratios")
    ap.add_argument("--one-process", choices=("none", "plain", "record"),
                    help="only warm up, then (plain / record) run episode 0 of each selected task without / with "
                         "recording, and exit: for an A/B across fresh processes under `perf stat -e task-clock` "
                         "(none: the warm-up alone, to subtract)")
    ap.add_argument("--json", help="also write the results to this JSON file")
    args = ap.parse_args(argv)

    from hexbench import recording
    from hexbench.suite.tasks import load_suite

    suite = load_suite("v1")
    if args.full:
        tasks, episodes = list(suite.tasks), None
    else:
        terrains = args.terrain or sorted(DEFAULT_LEVELS)
        if args.levels:
            levels = [float(v) for v in args.levels.split(",")]
            tasks = suite.select(terrains, levels)
        else:
            tasks = [suite.task(t, DEFAULT_LEVELS[t]) for t in terrains]
        episodes = args.episodes

    if args.one_process:
        _warm_up()
        if args.one_process != "none":
            _one_process(tasks, record=args.one_process == "record")
        return 0

    # Warm-up: a worker pays once for importing Rerun, parsing the URDF and building lookup
    # tables (~1 s); it is reported separately and kept out of the per-episode comparison.
    t0 = time.process_time()
    _warm_up()
    warm_up_cpu_s = time.process_time() - t0

    clock = {"recorder_s": 0.0}
    original = recording.make_episode_recorder
    recording.make_episode_recorder = lambda *a, **k: _TimedRecorder(original(*a, **k), clock)
    try:
        plain, recorded = [], []
        for i in range(args.repeats):
            # alternate which configuration runs first (ABBA...), so a drift in machine load or a
            # warm-cache advantage of the second run does not favour one side
            for record in ((False, True) if i % 2 == 0 else (True, False)):
                clock["recorder_s"] = 0.0
                run = _run(tasks, episodes, record, clock)
                if record:
                    run["recorder_s"] = clock["recorder_s"]
                (recorded if record else plain).append(run)
    finally:
        recording.make_episode_recorder = original

    med = statistics.median
    cpu_plain, cpu_rec = med(r["cpu_s"] for r in plain), med(r["cpu_s"] for r in recorded)
    wall_plain, wall_rec = med(r["wall_s"] for r in plain), med(r["wall_s"] for r in recorded)
    rec_s = med(r["recorder_s"] for r in recorded)
    sizes = recorded[-1]["sizes"]
    steps = recorded[-1]["steps"]
    totals = [s["mcap_bytes"] + s["rrd_bytes"] for s in sizes]
    n_steps = sum(steps.values())
    result = {
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "tasks": [t.name for t in tasks], "episodes": len(sizes), "control_steps": n_steps,
        "repeats": args.repeats,
        "cpu_s": {"no_record": cpu_plain, "record": cpu_rec, "ratio": cpu_rec / cpu_plain},
        "wall_s": {"no_record": wall_plain, "record": wall_rec, "ratio": wall_rec / wall_plain},
        "recorder_cpu_s": rec_s, "recorder_fraction_of_plain_cpu": rec_s / cpu_plain,
        "paired_ratio_median": {k: med(b[f"{k}_s"] / a[f"{k}_s"] for a, b in zip(plain, recorded))
                                for k in ("cpu", "wall")},
        "runs": {"no_record_cpu_s": [r["cpu_s"] for r in plain], "record_cpu_s": [r["cpu_s"] for r in recorded],
                 "no_record_wall_s": [r["wall_s"] for r in plain], "record_wall_s": [r["wall_s"] for r in recorded],
                 "recorder_cpu_s": [r["recorder_s"] for r in recorded]},
        "one_time_warm_up_cpu_s": warm_up_cpu_s,
        "bytes_per_episode": {
            "mcap_mean": statistics.mean(s["mcap_bytes"] for s in sizes),
            "rrd_mean": statistics.mean(s["rrd_bytes"] for s in sizes),
            "total_mean": statistics.mean(totals), "total_max": max(totals),
            "total_per_1000_steps": 1000 * sum(totals) / n_steps,
        },
        "per_episode": [{**s, "steps": steps.get(_row_key(s["episode"]), None)} for s in sizes],
        "load_average": list(os.getloadavg()),
    }
    if args.paired:
        result["paired_episode"] = _paired_episode(suite.task("stairs", 5.0), args.paired)
    if args.long_steps:
        result["long_episodes"] = [_long_episode(args.long_steps, noise) for noise in (0.0, 0.3)]
    b = result["bytes_per_episode"]
    print(f"tasks {', '.join(result['tasks'])}; {len(sizes)} episodes, {n_steps} control steps, {args.repeats} repeats")
    print(f"CPU time   no record {cpu_plain:8.2f} s   record {cpu_rec:8.2f} s   ratio {cpu_rec / cpu_plain:.3f}")
    print(f"wall time  no record {wall_plain:8.2f} s   record {wall_rec:8.2f} s   ratio {wall_rec / wall_plain:.3f}")
    print("per repeat, CPU s (no record / record): "
          + ", ".join(f"{a['cpu_s']:.2f}/{b['cpu_s']:.2f}" for a, b in zip(plain, recorded))
          + f"; median of the paired ratios: CPU {result['paired_ratio_median']['cpu']:.3f}, "
            f"wall {result['paired_ratio_median']['wall']:.3f}")
    print(f"recorder calls {rec_s:.2f} s CPU = {100 * rec_s / cpu_plain:.1f}% of the unrecorded CPU time; "
          f"one-time warm-up per worker {warm_up_cpu_s:.2f} s CPU (not included)")
    print(f"bytes/episode  mcap {b['mcap_mean'] / 1e3:.0f} kB  rrd {b['rrd_mean'] / 1e3:.0f} kB  "
          f"both: mean {b['total_mean'] / 1e3:.0f} kB, max {b['total_max'] / 1e3:.0f} kB "
          f"({b['total_per_1000_steps'] / 1e3:.0f} kB per 1000 steps)")
    for e in result["per_episode"]:
        print(f"  {e['episode']:<16} {e['steps'] or '?':>5} steps  mcap {e['mcap_bytes'] / 1e3:6.0f} kB  "
              f"rrd {e['rrd_bytes'] / 1e3:6.0f} kB")
    pe = result.get("paired_episode")
    if pe:
        print(f"one episode ({pe['steps']} steps) x {pe['pairs']} pairs: CPU with / without recording, median "
              f"{pe['cpu_ratio_median']:.3f} (quartiles {pe['cpu_ratio_quartiles'][0]:.3f}-"
              f"{pe['cpu_ratio_quartiles'][1]:.3f}); median CPU {pe['no_record_cpu_s_median']:.3f} -> "
              f"{pe['record_cpu_s_median']:.3f} s")
    for e in result.get("long_episodes", []):
        print(f"{e['steps']}-step episode, rough 6 cm, goal out of reach, "
              f"residual noise sigma {e['residual_noise']:g}: "
              f"mcap {e['mcap_bytes'] / 1e3:.0f} kB  rrd {e['rrd_bytes'] / 1e3:.0f} kB  "
              f"both {(e['mcap_bytes'] + e['rrd_bytes']) / 1e3:.0f} kB")
    print("load average (1, 5, 15 min) at the end: " + ", ".join(f"{v:.2f}" for v in result["load_average"]))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


def _warm_up() -> None:
    """Record one short episode so imports and per-process caches are in place before timing."""
    import numpy as np

    from hexbench.recording import make_episode_recorder
    from hexbench.world.env import HexapodEnv

    env = HexapodEnv(terrain="rough", level=6.0, max_steps=20)
    with tempfile.TemporaryDirectory(prefix="hexbench_bench_") as tmp:
        obs, _ = env.reset(seed=0)
        rec = make_episode_recorder(Path(tmp), "warm-up", {})
        rec.on_reset(env)
        while True:
            obs, reward, terminated, truncated, info = env.step(np.zeros(18))
            rec.on_step(env, obs, np.zeros(18), reward, info)
            if terminated or truncated:
                break
        rec.on_end({"steps": 20})
    env.close()


def _one_process(tasks, record: bool) -> None:
    from hexbench.evaluation.episode import EpisodeJob, run_episode
    from hexbench.suite.tasks import episode_seed

    with tempfile.TemporaryDirectory(prefix="hexbench_bench_") as tmp:
        for task in tasks:
            seed = episode_seed(task.protocol, task.terrain, task.level, 0)
            run_episode(EpisodeJob(str(CPG), task, 0, seed, record_dir=tmp if record else None))


def _paired_episode(task, pairs: int) -> dict:
    """One episode through the evaluator's own episode function, with and without recording, `pairs` times."""
    from hexbench.evaluation.episode import EpisodeJob, run_episode
    from hexbench.suite.tasks import episode_seed

    seed = episode_seed(task.protocol, task.terrain, task.level, 0)
    ratios, plain, recorded, steps = [], [], [], 0
    with tempfile.TemporaryDirectory(prefix="hexbench_bench_") as tmp:
        for i in range(pairs):
            cpu = {}
            for record in ((False, True) if i % 2 == 0 else (True, False)):
                job = EpisodeJob(str(CPG), task, 0, seed, record_dir=tmp if record else None)
                t0 = time.process_time()
                row = run_episode(job)
                cpu[record] = time.process_time() - t0
                steps = row["steps"]
            plain.append(cpu[False])
            recorded.append(cpu[True])
            ratios.append(cpu[True] / cpu[False])
    q = statistics.quantiles(ratios, n=4) if len(ratios) > 1 else [ratios[0]] * 3
    return {"task": task.name, "steps": steps, "pairs": pairs, "cpu_ratio_median": statistics.median(ratios),
            "cpu_ratio_quartiles": [q[0], q[2]], "cpu_ratios": ratios,
            "no_record_cpu_s_median": statistics.median(plain), "record_cpu_s_median": statistics.median(recorded)}


def _long_episode(steps: int, noise: float) -> dict:
    """Record one `steps`-step episode (goal out of reach, no lateral or fall end) and return its bytes."""
    import numpy as np

    from hexbench.recording import make_episode_recorder
    from hexbench.world.env import HexapodEnv

    env = HexapodEnv(terrain="rough", level=6.0, max_steps=steps, goal_distance_m=1000.0,
                     max_lateral_deviation_m=1000.0, fall_tilt_deg=180.0)
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory(prefix="hexbench_bench_") as tmp:
        obs, _ = env.reset(seed=7)
        rec = make_episode_recorder(Path(tmp), "rough-6cm-long", {"protocol": "v1", "terrain": "rough", "level": 6.0,
                                                                  "unit": "cm", "index": 0, "seed": 7})
        rec.on_reset(env)
        n = 0
        while True:
            action = np.clip(noise * rng.standard_normal(18), -1.0, 1.0) if noise else np.zeros(18)
            obs, reward, terminated, truncated, info = env.step(action)
            n += 1
            rec.on_step(env, obs, action, reward, info)
            if terminated or truncated:
                break
        files = rec.on_end({"steps": n, "end_reason": info["end_reason"]})
        out = {"steps": n, "end_reason": info["end_reason"], "residual_noise": noise,
               "mcap_bytes": (Path(tmp) / files["mcap_path"]).stat().st_size,
               "rrd_bytes": (Path(tmp) / files["rrd_path"]).stat().st_size}
    env.close()
    return out


def _row_key(episode_id: str) -> str:
    """'stairs-5cm-00' -> 'stairs-5-00' (the key used for steps)."""
    terrain, level_unit, index = episode_id.rsplit("-", 2)
    level = level_unit.rstrip("cmdeg")
    return f"{terrain}-{float(level):g}-{index}"


if __name__ == "__main__":
    sys.exit(main())
