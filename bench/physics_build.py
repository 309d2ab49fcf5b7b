"""One PyBullet build against another: CPU time per control step on the same protocol episodes,
and whether both still play every episode exactly as the committed record holds it.

    pip wheel --no-deps --no-binary pybullet "pybullet==3.2.7" -w build/pybullet-src   # PyBullet built here
    python bench/physics_build.py --other build/pybullet-src/pybullet-3.2.7-cp311-cp311-linux_x86_64.whl
    python bench/physics_build.py --other DIR --rounds 3 --episodes 2

`--other` is a pybullet wheel or a folder holding a built `pybullet*.so`; a child process given
that folder (or the wheel's extension module, unpacked) first on its PYTHONPATH imports that build
instead of the installed one. Each round runs two children at once, one pinned to each of the
first two cores this process may use: the installed build on the first and the other on the
second, then swapped, so both builds meet the same load and the same core. Each child plays the
same PPO-CPG episodes of protocol v1 (episode indexes 0 .. N-1 of six levels across rough, slopes
and stairs, as `hexbench run` seeds them) in one process, the controller in-process with the
evaluation worker's capped math, and times each episode's CPU (`time.process_time`). The ratio is
other / installed CPU per control step, per round and as the median of rounds. Every row each child
plays must equal, field for field, the row of leaderboard/ppo_cpg.json for the same episode:
a build that changes any bit of the physics changes those rows, and the script says which.
Writes bench/out/physics_build.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
RECORD = REPO / "leaderboard" / "ppo_cpg.json"
CONTROLLER = REPO / "baselines" / "ppo_cpg.py"
LEVELS: tuple[tuple[str, float], ...] = (("rough", 3.0), ("rough", 7.0), ("slopes", 9.0), ("slopes", 15.0),
                                        ("stairs", 4.0), ("stairs", 7.0))


def play_episodes(episodes: int, slot: int, out: Path) -> None:
    """Child: pinned to the `slot`-th allowed core, play the episodes with whichever pybullet this process
    imports; write their times and checks."""
    from hexbench.evaluation.workers import pin_to_core
    from hexbench.suite.numerics import use_controller_math

    pin_to_core(slot)

    use_controller_math()
    import pybullet

    from hexbench.evaluation.episode import first_row_difference
    from hexbench.suite.controller import make_controller
    from hexbench.suite.rollout import LocalActor, play
    from hexbench.suite.tasks import episode_seed, load_suite

    record = json.loads(RECORD.read_text())
    committed = {(r["terrain"], r["level"], r["index"]): r for r in record["episodes"]}
    suite = load_suite(record["protocol"])
    rows = []
    for terrain, level in LEVELS:
        task = suite.task(terrain, level)
        actor = LocalActor(make_controller(CONTROLLER, task))
        for index in range(episodes):
            seed = episode_seed(record["protocol"], terrain, level, index)
            started_cpu_s = time.process_time()
            episode = play(task, seed, actor, index=index, controller_seed=0)
            cpu_s = time.process_time() - started_cpu_s
            difference = first_row_difference(committed[(terrain, level, index)], episode.row)
            rows.append({"terrain": terrain, "level": level, "index": index, "steps": episode.row["steps"],
                         "cpu_s": cpu_s, "difference_from_record": difference})
    out.write_text(json.dumps({"pybullet": pybullet.__file__, "episodes": rows}))


def run_pair(other: Path, episodes: int, installed_slot: int, folder: Path, tag: str) -> dict[str, dict]:
    """Both builds at once, the installed one pinned to the `installed_slot`-th allowed core (0 or 1) and the other
    to the other of the first two; their children's reports by build."""
    procs = {}
    for build, slot in (("installed", installed_slot), ("other", 1 - installed_slot)):
        env = dict(os.environ)
        if build == "other":
            env["PYTHONPATH"] = os.pathsep.join([str(other)] + [p for p in [env.get("PYTHONPATH")] if p])
        out = folder / f"{tag}-{build}.json"
        cmd = [sys.executable, __file__, "--child", str(out), "--slot", str(slot), "--episodes", str(episodes)]
        procs[build] = (subprocess.Popen(cmd, env=env, cwd=REPO), out)
    reports = {}
    for build, (proc, out) in procs.items():
        if proc.wait() != 0:
            sys.exit(f"physics_build: the {build} build's child failed (exit {proc.returncode})")
        reports[build] = json.loads(out.read_text())
    return reports


def other_build_folder(other: Path | None, scratch: Path) -> Path:
    """A folder whose pybullet*.so shadows the installed build: --other itself, or its wheel's module unpacked."""
    if other is not None and other.is_file() and other.suffix == ".whl":
        try:
            with zipfile.ZipFile(other) as wheel:
                modules = [n for n in wheel.namelist()
                           if "/" not in n and n.startswith("pybullet") and n.endswith(".so")]
                if modules:
                    wheel.extract(modules[0], scratch / "other")
                    return (scratch / "other").resolve()
        except zipfile.BadZipFile:
            pass
        sys.exit(f"physics_build: {other} is not a pybullet wheel with its extension module")
    if other is None or not other.is_dir() or not any(other.glob("pybullet*.so")):
        sys.exit(f"physics_build: --other must name a pybullet wheel or a folder holding a pybullet*.so "
                 f"(got {other})")
    return other.resolve()


def us_per_step(report: dict) -> float:
    rows = report["episodes"]
    return 1e6 * sum(r["cpu_s"] for r in rows) / sum(r["steps"] for r in rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--other", type=Path,
                        help="the other pybullet build: a wheel, or a folder holding a pybullet*.so")
    parser.add_argument("--episodes", type=int, default=2, help="episodes per level [count]")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of two swapped pairs")
    parser.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--slot", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        play_episodes(args.episodes, args.slot, args.child)
        return
    if len(os.sched_getaffinity(0)) < 2:
        sys.exit("physics_build: needs two cores to run both builds at once")
    rounds = []
    with tempfile.TemporaryDirectory() as tmp:
        other_folder = other_build_folder(args.other, Path(tmp))
        for r in range(args.rounds):
            halves = [run_pair(other_folder, args.episodes, slot, Path(tmp), f"{r}-{slot}") for slot in (0, 1)]
            installed = [us_per_step(h["installed"]) for h in halves]
            other = [us_per_step(h["other"]) for h in halves]
            differing = sorted({f"{b}: {e['terrain']} {e['level']:g} #{e['index']} ({e['difference_from_record']})"
                                for h in halves for b in h for e in h[b]["episodes"] if e["difference_from_record"]})
            rounds.append({"installed_us_per_step": installed, "other_us_per_step": other,
                           "ratio": sum(other) / sum(installed), "differing_episodes": differing,
                           "builds": {b: halves[0][b]["pybullet"] for b in halves[0]},
                           "steps_per_child": sum(e["steps"] for e in halves[0]["installed"]["episodes"])})
            print(f"round {r + 1}: installed {installed[0]:.0f}, {installed[1]:.0f} us/step; other {other[0]:.0f}, "
                  f"{other[1]:.0f} us/step; other / installed {rounds[-1]['ratio']:.3f}; "
                  f"rows equal to the record: {'all' if not differing else 'NOT ' + '; '.join(differing)}", flush=True)
    summary = {"median_ratio": statistics.median(r["ratio"] for r in rounds),
               "all_rows_equal_record": not any(r["differing_episodes"] for r in rounds),
               "episodes_per_level": args.episodes, "levels": [list(x) for x in LEVELS], "rounds": rounds,
               "command": " ".join([Path(sys.argv[0]).as_posix()] + sys.argv[1:])}
    print(f"median other / installed CPU per control step: {summary['median_ratio']:.3f}; "
          f"every row equal to the committed record's: {summary['all_rows_equal_record']}")
    out = REPO / "bench" / "out" / "physics_build.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
