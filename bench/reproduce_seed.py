"""Does a seed run reproduce? A re-training of one seed by its documented command, set against the
committed run of that seed and against its method's interval across seeds.

    python bench/reproduce_seed.py baselines/reproduction/ppo_cpg-stairs-seed1

The argument is a seed-run folder (same layout as baselines/seeds/<method>-<terrain>-seed<S>/:
checkpoints/ with the manifest entry, training/, result-<terrain>.json) made from scratch with the
command in its manifest entry. Reported: whether the selected checkpoint is byte-identical to the
committed run's, how many of the record's episodes agree (success, end reason, steps, action-log
sha256), and where the re-run's AUC and its success over the terrain's levels (interquartile mean
over the levels, the statistic of the method's row) fall against the method's interquartile mean and
its 95% stratified-bootstrap interval over the committed seeds (the seeds page's figures). Writes bench/out/reproduce_seed.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from hexbench.leaderboard import statistics
from hexbench.leaderboard.seeds import SEEDS_DIR, aggregate, load_seed_runs, read_seed_run
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


def _episodes(folder: Path, terrain: str) -> dict:
    record = json.loads((folder / f"result-{terrain}.json").read_text())
    return {(e["level"], e["index"]): e for e in record["episodes"]}


def _selected(folder: Path) -> dict:
    manifest = json.loads((folder / "checkpoints" / "manifest.json").read_text())
    (entry,) = manifest["checkpoints"].values()
    return entry


def _training_end(folder: Path) -> dict:
    """The run's last checkpoint as its run.json states it: env steps, training episodes and metrics, and
    the wall time of the whole run [s] (a manifest entry's wall time is its selected checkpoint's)."""
    run = json.loads((folder / "training" / "run.json").read_text())
    last = run["checkpoints"][-1]
    return {k: last.get(k) for k in ("env_steps", "episodes", "success_rate", "mean_episode_reward", "wall_time_s")}


def _learned(end: dict) -> tuple:
    return end["env_steps"], end["episodes"], end["success_rate"], end["mean_episode_reward"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rerun", type=Path, help="the re-trained seed-run folder")
    parser.add_argument("--seeds-dir", type=Path, default=REPO / SEEDS_DIR, help="the committed seed runs")
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "out" / "reproduce_seed.json")
    args = parser.parse_args()

    rerun = read_seed_run(args.rerun)
    if rerun is None:
        raise SystemExit(f"{args.rerun}: its record is not of the default protocol")
    original_folder = args.seeds_dir / args.rerun.name
    original = read_seed_run(original_folder)
    suite = load_suite("v1")
    committed = load_seed_runs(args.seeds_dir).runs
    (agg,) = [a for a in aggregate(committed, suite)
              if a.terrain == rerun.terrain and a.method.label == rerun.method
              and a.method.budget_env_steps == rerun.budget_env_steps]

    new_entry, old_entry = _selected(args.rerun), _selected(original_folder)
    new_eps, old_eps = _episodes(args.rerun, rerun.terrain), _episodes(original_folder, rerun.terrain)
    keys = ("success", "end_reason", "steps", "action_log_sha256")
    same = sum(all(new_eps[k].get(f) == old_eps[k].get(f) for f in keys) for k in old_eps if k in new_eps)
    auc = float(rerun.row.terrain(rerun.terrain)["auc"])
    # the statistic of the method's row (IQM over runs x levels), applied to this one run's levels
    success = statistics.interquartile_mean([rerun.scores(list(agg.levels))])
    report = {
        "rerun": str(args.rerun), "original": str(original_folder),
        "command": new_entry.get("command"),
        "checkpoint_identical": new_entry["sha256"] == old_entry["sha256"],
        "selected_env_steps": {"rerun": new_entry.get("env_steps"), "original": old_entry.get("env_steps")},
        "episodes_identical": same, "episodes": len(old_eps),
        "training_end": {"rerun": _training_end(args.rerun), "original": _training_end(original_folder)},
        "auc": {"rerun": auc, "original": float(original.row.terrain(rerun.terrain)["auc"]),
                "method_iqm": agg.auc.value, "method_interval_95": [agg.auc.low, agg.auc.high],
                "inside": agg.auc.low <= auc <= agg.auc.high,
                "per_seed": {r.seed: float(r.row.terrain(rerun.terrain)["auc"]) for r in agg.runs}},
        "success_over_levels": {"rerun": success, "method_iqm": agg.all_levels.value,
                                "method_interval_95": [agg.all_levels.low, agg.all_levels.high],
                                "inside": agg.all_levels.low <= success <= agg.all_levels.high},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    a, s = report["auc"], report["success_over_levels"]
    print(f"{agg.method.name}, {rerun.terrain}, seed {rerun.seed}: checkpoint "
          f"{'byte-identical to' if report['checkpoint_identical'] else 'differs from'} the committed run's "
          f"(selected at {new_entry.get('env_steps'):,} / {old_entry.get('env_steps'):,} env steps); "
          f"{same} of {len(old_eps)} episodes identical")
    t = report["training_end"]
    print(f"training at {t['rerun']['env_steps']:,} env steps: {t['rerun']['episodes']} episodes (committed run: "
          f"{t['original']['episodes']}){', so the two trainings diverged' if _learned(t['rerun']) != _learned(t['original']) else ''}")
    print(f"AUC {a['rerun']:.3f} (committed {a['original']:.3f}); method IQM {a['method_iqm']:.3f}, "
          f"95% interval [{a['method_interval_95'][0]:.3f}, {a['method_interval_95'][1]:.3f}]: "
          f"{'inside' if a['inside'] else 'OUTSIDE'}")
    print(f"success over levels (IQM) {s['rerun']:.3f}; method IQM {s['method_iqm']:.3f}, 95% interval "
          f"[{s['method_interval_95'][0]:.3f}, {s['method_interval_95'][1]:.3f}]: {'inside' if s['inside'] else 'OUTSIDE'}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
