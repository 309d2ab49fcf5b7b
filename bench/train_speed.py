"""Training throughput: env steps per second of wall-clock time for PPO, SAC and TD3 with 1 and 2 workers.

Each case is a fresh `hexbench.training.loop.train` run (the real training path: curriculum env with noise,
Monitor, fixed observation scaling, SB3 learner, our callback) on rough terrain, timed by the run's
own wall clock (the `learn` call, not start-up). PPO uses baselines/ppo_cpg.py's CONFIG with
n_steps shortened so every case completes whole rollouts; SAC and TD3 use baselines/sac_cpg.py's and
td3_cpg.py's CONFIG with learning_starts shortened so most steps include a gradient update (the steady state of a
long run). Wall-clock rates depend on what else the machine runs: the 1-minute load average
before and after each case is printed and saved with the numbers.

    python bench/train_speed.py                          # PPO and SAC, 1 and 2 workers, 4096 steps each
    python bench/train_speed.py --algos ppo --workers 1 --steps 2048 --json bench/out/train_speed.json
    python bench/train_speed.py --algos sac --workers 1 --set train_freq=4 --set "critic_net_arch=(256, 256)"
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
from pathlib import Path

from hexbench.training.loop import train
from hexbench.training.runs import read_run
from hexbench.training.settings import TrainSettings, parse_override

REPO = Path(__file__).resolve().parent.parent
CASES = {  # algo -> (baseline file, config overrides making a short run representative)
    "ppo": (REPO / "baselines" / "ppo_cpg.py", (("n_steps", 512),)),
    "sac": (REPO / "baselines" / "sac_cpg.py", (("learning_starts", 256),)),
    "td3": (REPO / "baselines" / "td3_cpg.py", (("learning_starts", 256),)),
}


def measure(algo: str, workers: int, steps: int, seed: int = 0, extra: tuple = ()) -> dict:
    baseline, overrides = CASES[algo]
    overrides = tuple(overrides) + tuple(extra)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        settings = TrainSettings(baseline_path=baseline, terrain="rough", total_steps=steps, seed=seed,
                                 workers=workers, out_dir=Path(tmp) / "run", overrides=overrides,
                                 show_progress=False, checkpoint_every_s=1e9, csv_every_s=1e9)
        train(settings)
        run = read_run(settings.run_dir)
    env_steps, wall = run["env_steps"], run["wall_time_s"]
    return {"algo": algo, "baseline": baseline.name, "overrides": [f"{k}={v!r}" for k, v in overrides],
            "workers": workers, "env_steps": env_steps,
            "wall_time_s": wall, "env_steps_per_s": env_steps / wall, "load1_before": load_before,
            "load1_after": os.getloadavg()[0]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algos", default="ppo,sac", help="comma-separated subset of: " + ", ".join(CASES))
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    parser.add_argument("--steps", type=int, default=4096, help="env steps per case (summed over workers)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="a config override for every case (repeatable), as `hexbench train --set`")
    parser.add_argument("--json", type=Path, default=None, help="also write the results here")
    args = parser.parse_args()
    algos = [a for a in args.algos.split(",") if a]
    unknown = [a for a in algos if a not in CASES]
    if unknown:
        print(f"unknown algo(s) {unknown}; valid: {', '.join(CASES)}", file=sys.stderr)
        return 2
    extra = tuple(parse_override(t) for t in args.set)
    results = []
    for algo in algos:
        for workers in (int(w) for w in args.workers.split(",")):
            r = measure(algo, workers, args.steps, extra=extra)
            results.append(r)
            print(f"{algo:4s} workers={workers}  {r['env_steps']:6d} steps in {r['wall_time_s']:7.1f} s  "
                  f"-> {r['env_steps_per_s']:7.1f} env steps/s   (load avg {r['load1_before']:.1f} -> "
                  f"{r['load1_after']:.1f} on {os.cpu_count()} cores)", flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"machine": platform.platform(), "cpus": os.cpu_count(),
                                         "python": platform.python_version(), "results": results}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
