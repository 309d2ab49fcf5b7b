"""One seed run of a baseline file's recipe, from scratch to its admitted record, as one command:

    hexbench seed-run baselines/sac.py --terrain stairs --seed 1

makes baselines/seeds/sac-stairs-seed1/ (the layout of baselines/seeds/README.md) through the
stages every committed seed run went through, each resumable (run the command again after a stop):
1. train the file's CONFIG as it is (no overrides: the recipe is the file) for the budget, a
   checkpoint every 125,000 env steps so a run makes the same checkpoints on any machine
   (`hexbench.training.loop.train`), into training/<method>-<terrain>-seed<S>/;
2. play held-out episodes for every checkpoint (`hexbench.training.selection.select`: 3 per
   selection level, never a protocol seed) and take the best;
3. publish it (acting weights and manifest entry) beside a byte-identical copy of the baseline file
   in the scoring folder runs/seed-runs/<name>/, so that file scores exactly these weights;
4. score it on every protocol level of the terrain, sandboxed (`hexbench.evaluation.evaluate`;
   the action logs stay in runs/seed-runs/<name>/run/ for `hexbench verify`);
5. admit the record by replaying episodes from their action logs (`add_seed_run`), move the folder
   (checkpoints/, training/ with run.json, progress.csv and selection.json, result-<terrain>.json)
   into the seeds folder in one rename, and write the run's row of <method>-runs.csv there.

A stage that fails raises a HexbenchError and writes nothing under the seeds folder; a seed-run
folder that exists already is never overwritten (a seed run is made once).
"""

from __future__ import annotations

import csv
import os
import shlex
import shutil
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from hexbench.agents.policy import config_dict
from hexbench.artifacts.files import check_writable, make_folder, os_reason, write_bytes_atomic
from hexbench.errors import HexbenchError, OutputError
from hexbench.evaluation.evaluate import evaluate
from hexbench.leaderboard.admission import add_seed_run
from hexbench.leaderboard.seeds import SEEDS_DIR
from hexbench.suite.tasks import load_suite
from hexbench.training.batch import RUNS_COLUMNS, summary_row, write_runs_csv
from hexbench.training.loop import train
from hexbench.training.publish import publish_checkpoint
from hexbench.training.runs import check_resume, read_run
from hexbench.training.selection import select
from hexbench.training.settings import TrainSettings, check_settings, load_run_config

BUDGET_ENV_STEPS = 1_000_000  # one budget for every method on the seeds page
CHECKPOINT_EVERY_ENV_STEPS = 125_000  # 8 checkpoints per 1M-step run to select among
REPLAY_SAMPLE = 40  # episodes replayed from their action logs before the record is admitted
SCORING_ROOT = Path("runs") / "seed-runs"  # the scoring folders (git-ignored), one per seed run
TRAINING_FILES = ("run.json", "progress.csv", "selection.json")  # what of training/<name>/ the folder keeps
# `hexbench seed-run` options that change what a run makes or where it lands, and their plan fields
COMMAND_OPTIONS = (("--steps", "budget_env_steps"), ("--workers", "workers"), ("--sample", "replay_sample"),
                   ("--seeds-dir", "seeds_dir"), ("--training-dir", "training_root"), ("--scoring-dir", "scoring_root"))


class SeedPipelineError(HexbenchError):
    """A seed run that cannot be made or admitted."""


@dataclass(frozen=True)
class SeedRunPlan:
    """What one `hexbench seed-run` makes and where."""

    baseline_path: Path
    terrain: str
    seed: int
    budget_env_steps: int = BUDGET_ENV_STEPS
    checkpoint_every_env_steps: int = CHECKPOINT_EVERY_ENV_STEPS
    training_root: Path = Path("training")
    scoring_root: Path = SCORING_ROOT
    seeds_dir: Path = SEEDS_DIR
    workers: int = 1  # processes for the held-out episodes, the protocol episodes and the replay
    replay_sample: int | None = REPLAY_SAMPLE  # None: replay every episode
    show_progress: bool = True

    def train_settings(self) -> TrainSettings:
        return TrainSettings(baseline_path=Path(self.baseline_path), terrain=self.terrain,
                             total_steps=self.budget_env_steps, seed=self.seed,
                             out_dir=self.run_dir, checkpoint_every_steps=self.checkpoint_every_env_steps,
                             command=self.command, show_progress=self.show_progress)

    @property
    def command(self) -> str:
        """The `hexbench seed-run` command that makes this run: the options away from their defaults, in
        one order (recorded in run.json and the manifest entry)."""
        parts = ["hexbench", "seed-run", str(self.baseline_path), "--terrain", self.terrain, "--seed", str(self.seed)]
        for flag, name in COMMAND_OPTIONS:
            value, default = getattr(self, name), next(f.default for f in fields(self) if f.name == name)
            if value != default:
                parts += [flag, "0" if value is None else str(value)]
        return shlex.join(parts)

    @property
    def method(self) -> str:
        return Path(self.baseline_path).stem

    @property
    def name(self) -> str:
        return f"{self.method}-{self.terrain}-seed{self.seed}"

    @property
    def run_dir(self) -> Path:
        return Path(self.training_root) / self.name

    @property
    def destination(self) -> Path:
        return Path(self.seeds_dir) / self.name

    @property
    def scoring_folder(self) -> Path:
        return Path(self.scoring_root) / self.name


def make_seed_run(plan: SeedRunPlan, say: Callable[[str], None] = lambda _line: None) -> Path:
    """Make, score and admit one seed run (module docstring); returns its folder under the seeds folder."""
    settings = plan.train_settings()
    config = _check_plan(plan, settings)
    run_dir = settings.run_dir
    run = read_run(run_dir)
    if run is not None:  # a run to resume or take as it is: the file's recipe, not a run made otherwise
        check_resume(run_dir, run, settings, config_dict(config))
    if run is None or run["env_steps"] < plan.budget_env_steps:
        say(f"1/5 training {plan.name}: {plan.budget_env_steps:,} env steps, a checkpoint every "
            f"{plan.checkpoint_every_env_steps:,} ({run_dir})")
        train(settings)
    else:
        say(f"1/5 training {plan.name}: done before ({run['env_steps']:,} env steps)")
    say("2/5 held-out episodes for every checkpoint")
    table = select(run_dir, workers=plan.workers, progress=plan.show_progress)
    best = table["best"]
    scoring = plan.scoring_folder
    say(f"3/5 publishing the held-out best ({best['env_steps']:,} env steps) into {scoring}")
    make_folder(scoring)
    controller = scoring / Path(plan.baseline_path).name
    write_bytes_atomic(controller, Path(plan.baseline_path).read_bytes())
    publish_checkpoint(run_dir, scoring / "checkpoints", "heldout")
    say(f"4/5 scoring it on every {plan.terrain} level of the protocol, sandboxed")
    tasks = load_suite().select([plan.terrain])
    result = evaluate(controller, tasks, scoring / "run", workers=plan.workers, record=False, label=plan.method,
                      progress=plan.show_progress, command=plan.command)
    if result.error:
        raise SeedPipelineError(result.error)
    say(f"5/5 replaying {plan.replay_sample or 'every'} episodes from their action logs and admitting the record")
    make_folder(scoring / "training")
    for name in TRAINING_FILES:
        write_bytes_atomic(scoring / "training" / name, (run_dir / name).read_bytes())
    record = add_seed_run(scoring / "run", scoring, sample=plan.replay_sample, workers=plan.workers,
                          progress=plan.show_progress)
    make_folder(plan.seeds_dir)
    _install(scoring, record, plan.destination)
    _write_row(plan, settings)
    return plan.destination


def _check_plan(plan: SeedRunPlan, settings: TrainSettings):
    """Before hours of training: the terrain, the seed, the file's recipe (returned: its CONFIG) and a free,
    writable destination."""
    if plan.seed < 0:
        raise SeedPipelineError(f"--seed {plan.seed}: a seed run's seed is >= 0")
    check_settings(settings)
    config = load_run_config(settings)  # the file and its CONFIG, as training will read them
    if plan.destination.exists():
        raise SeedPipelineError(f"{plan.destination}: exists; a seed run is made once (remove the folder, or "
                                f"choose another --seed)")
    existing = Path(plan.seeds_dir)
    while not existing.exists() and existing != existing.parent:  # the folder, or where it will be made
        existing = existing.parent
    check_writable(existing, named=plan.seeds_dir)
    return config


def _install(scoring: Path, record: Path, destination: Path) -> None:
    """checkpoints/, training/ and the record of the scoring folder into `destination`, in one rename."""
    staging = destination.with_name(f".{destination.name}.partial")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        shutil.copytree(scoring / "checkpoints", staging / "checkpoints")
        shutil.copytree(scoring / "training", staging / "training")
        shutil.copyfile(record, staging / record.name)
        os.rename(staging, destination)  # fails if destination appeared meanwhile: never overwritten
    except OSError as e:
        shutil.rmtree(staging, ignore_errors=True)
        raise OutputError(f"{destination}: cannot be written ({os_reason(e)})") from None


def _write_row(plan: SeedRunPlan, settings: TrainSettings) -> None:
    """The run's row in <seeds folder>/<method>-runs.csv (a row of the same terrain and seed is replaced)."""
    path = Path(plan.seeds_dir) / f"{plan.method}-runs.csv"
    rows: list[dict] = []
    if path.exists():
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f)
                    if (r.get("terrain"), r.get("seed")) != (plan.terrain, str(plan.seed))]
    row = summary_row(settings, None)
    rows.append({k: row.get(k) for k in RUNS_COLUMNS})
    write_runs_csv(path, rows)
