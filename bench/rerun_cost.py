"""What checking a run by re-running its controller costs, against replaying it.

    python bench/rerun_cost.py RUN_DIR                  # e.g. a run of 20 episodes, 2 rounds
    python bench/rerun_cost.py RUN_DIR --rounds 3 --workers 2

Times, alternating round by round so that load drifts hit both alike:

  replay   `hexbench verify RUN_DIR`: every episode re-simulated from its action log alone;
  re-run   `hexbench verify RUN_DIR --rerun`: the record's checks without the physics, then the
           controller plays every episode in the sandbox and must choose every recorded action and
           find every recorded row (which replays them: the physics runs once).

Before the re-run replayed the episodes itself, `--rerun` cost a replay plus a re-run. Both
commands must succeed on RUN_DIR (an honest run). Prints the medians and writes
bench/out/rerun_cost.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

OUT = Path(__file__).resolve().parent / "out"


def timed(command: list[str]) -> float:
    """Wall time [s] of a command that must succeed."""
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(command)} failed (exit {done.returncode}): {done.stdout[-400:]}{done.stderr[-400:]}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    verify = [sys.executable, "-m", "hexbench", "verify", str(args.run_dir), "--workers", str(args.workers)]
    times: dict[str, list[float]] = {"replay": [], "re-run": []}
    for round_ in range(args.rounds):
        times["replay"].append(timed(verify))
        times["re-run"].append(timed([*verify, "--rerun"]))
        print(f"round {round_ + 1}: replay {times['replay'][-1]:.1f} s, re-run {times['re-run'][-1]:.1f} s")
    medians = {mode: statistics.median(values) for mode, values in times.items()}
    print(f"median: replay {medians['replay']:.1f} s, re-run {medians['re-run']:.1f} s; before the re-run replayed "
          f"the episodes itself, --rerun cost both: {medians['replay'] + medians['re-run']:.1f} s")
    episodes = len(json.loads((args.run_dir / "result.json").read_text())["episodes"])
    OUT.mkdir(exist_ok=True)
    (OUT / "rerun_cost.json").write_text(json.dumps({"run_dir": str(args.run_dir), "episodes": episodes,
                                                     "workers": args.workers, "times_s": times,
                                                     "median_s": medians}, indent=2) + "\n")


if __name__ == "__main__":
    main()
