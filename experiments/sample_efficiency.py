"""Sample efficiency of one method against another: env steps to reach a curriculum level.

"The same success on the same terrain level" is read through the paper's curriculum: a run reaches
level L when one of its envs has made 20 successful arrivals at every level below L (section 4.1).
For each run (a training run directory or a progress CSV with its .run.json beside it) this prints
the first logged env-step count at which the curriculum level is >= L. A run that never got there
is censored: it needed more than its last logged step count, and a ratio built on it is a lower
bound (printed with ">").

    python experiments/sample_efficiency.py --level 6 --reference ppo \\
        leaderboard/curves/ppo_cpg-rough-seed{0,1,2}-v4.csv leaderboard/curves/ppo-rough-seed{0,1,2}-v3.csv

Ratio = median steps of the reference method / median steps of each other method (> 1: the other
method needs fewer env steps). Runs of one method whose configs differ (an ablation) form separate
groups, labelled by the fields that differ:

    python experiments/sample_efficiency.py --level 11 --reference "ppo_cpg{log_std_init=-2.3}" \\
        leaderboard/curves/ppo_cpg-rough-seed{0,1,2}-v4.csv leaderboard/curves/ppo_cpg-rough-seed{0,1}-std05.csv

Progress rows are written once a minute, so a step count is exact
to about one minute of training.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import pandas as pd


def load(source: Path) -> tuple[pd.DataFrame, dict]:
    source = Path(source)
    csv_path, run_path = ((source / "progress.csv", source / "run.json") if source.is_dir()
                          else (source, source.with_suffix(".run.json")))
    if not csv_path.is_file() or not run_path.is_file():
        sys.exit(f"{source}: needs a progress CSV and its run.json (looked for {csv_path} and {run_path})")
    return pd.read_csv(csv_path), json.loads(run_path.read_text())


def steps_to_level(progress: pd.DataFrame, level: float) -> tuple[int, bool]:
    """(env steps, reached): first logged env steps with curriculum level >= level, else the last logged."""
    per_step = progress.groupby("env_steps")["curriculum_level"].max()
    reached = per_step[per_step >= level - 1e-9]
    if len(reached):
        return int(reached.index[0]), True
    return int(per_step.index.max()), False


def group_labels(runs: list[dict]) -> list[str]:
    """A label per run: its method, plus the config fields in which runs of that method and terrain
    differ, e.g. "ppo_cpg{log_std_init=-3.0}" beside "ppo_cpg{log_std_init=-2.3}" (an ablation).
    Runs are only compared within one label, so configs never mix in a median."""
    configs: dict[tuple[str, str], list[dict]] = {}
    for run in runs:
        configs.setdefault((run["method"], run["terrain"]), []).append(run["config"])
    differing = {key: sorted({k for c in group for k in c if any(c.get(k) != other.get(k) for other in group)})
                 for key, group in configs.items()}
    labels = []
    for run in runs:
        # a field a run's config lacks (added to the baseline file after that run) is left out of its
        # label, so older runs keep the labels the docs quote
        tag = ",".join(f"{k}={run['config'][k]}" for k in differing[(run["method"], run["terrain"])]
                       if k in run["config"])
        labels.append(f"{run['method']}{{{tag}}}" if tag else run["method"])
    return labels


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sources", nargs="+", type=Path)
    ap.add_argument("--level", type=float, default=6.0, help="curriculum level to reach (paper units)")
    ap.add_argument("--reference", default="ppo",
                    help="label (method, or method{field=value,...} when configs differ) the others are compared with")
    args = ap.parse_args()

    loaded = [(source, *load(source)) for source in args.sources]
    labels = group_labels([run for _, _, run in loaded])
    by_label: dict[tuple[str, str], list[tuple[int, bool, str]]] = {}
    for (source, progress, run), label in zip(loaded, labels):
        steps, reached = steps_to_level(progress, args.level)
        by_label.setdefault((label, run["terrain"]), []).append((steps, reached, str(source)))
        mark = "" if reached else " (not reached: censored)"
        print(f"{label} {run['terrain']} seed {run['seed']}: "
              f"{'' if reached else '>'}{steps:,} env steps to level {args.level:g}{mark}  [{source}]")

    known = sorted({label for label, _ in by_label})
    if args.reference not in known:
        sys.exit(f"--reference {args.reference!r} matches no run; labels here: {', '.join(known)}")
    for (label, terrain), runs in sorted(by_label.items()):
        if label == args.reference or (args.reference, terrain) not in by_label:
            continue
        ref = by_label[(args.reference, terrain)]
        ref_median = statistics.median(s for s, _, _ in ref)
        median = statistics.median(s for s, _, _ in runs)
        ref_censored = not all(r for _, r, _ in ref)
        censored = not all(r for _, r, _ in runs)
        if censored:  # its median is then a lower bound too, and the ratio bounds nothing
            print(f"{terrain}: {label} has runs that never reached level {args.level:g}; no ratio")
            continue
        bound = ">" if ref_censored else ""
        print(f"{terrain}: {args.reference} / {label} = {bound}{ref_median / median:.1f}x "
              f"(median env steps to level {args.level:g}: {args.reference} {bound}{ref_median:,.0f} over {len(ref)} run(s), "
              f"{label} {median:,.0f} over {len(runs)} run(s))")


if __name__ == "__main__":
    main()
