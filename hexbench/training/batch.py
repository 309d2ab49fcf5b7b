"""A batch of training runs, one per (terrain, seed), on this machine or on a Ray cluster.

    hexbench train baselines/ppo_cpg.py --terrain rough,slopes --seeds 0-4 --steps 1000000
    hexbench train baselines/ppo_cpg.py --terrain rough --seeds 0-4 --engine ray --address HOST:6379

Each run is an ordinary `hexbench train` run (`hexbench.training.loop.train`) in its usual folder,
OUT/<method>-<terrain>-seed<S> (OUT defaults to training/), so it resumes, is selected and
published exactly as a run started by hand; its run.json records the single-run command that
continues it (`hexbench train FILE --terrain T --seed S --out OUT/...`), and OUT/<method>-runs.csv
sums the batch up (RUNS_COLUMNS). Running the batch command again resumes every unfinished run and
leaves finished ones as they are.

Where the runs play (`hexbench.evaluation.engines`):
- local (the default): `--parallel N` runs at once, each in a process of its own with its
  `--workers` env processes; N defaults to the cores divided by `--workers` (one run per core).
- ray: every run is one Ray task that asks for `--workers` CPUs (and a GPU with `--device cuda`),
  so the cluster places as many at once as its resources hold. The task changes into the driver's
  working folder, so the baseline file and the Python environment must be at the same paths on
  every node. With a shared filesystem (NFS and the like: the usual cluster set-up) checkpoints and
  CSVs land in the run folders as they are written, and a run whose node dies is run again on
  another node from its last checkpoint. Without one, a run writes on its node and ships its
  folder back to the driver when it ends (a run lost with its node then starts over elsewhere).
  Which of the two holds is found out per task: the driver leaves a random token in OUT, and a task
  that reads the same token there shares the driver's files.

A run that fails (a TrainError, an exception in the learner) is a row with its one-line error; the
others go on, and the batch ends with exit 1 naming the failed runs.
"""

from __future__ import annotations

import csv
import os
import secrets
import threading
from dataclasses import dataclass, replace
from pathlib import Path

from hexbench.artifacts.files import atomic_path, write_bytes_atomic, write_text_atomic
from hexbench.training.runs import read_run
from hexbench.training.settings import TRAIN_TERRAINS, TrainError, TrainSettings, check_settings, load_run_config

RUNS_COLUMNS = ("terrain", "seed", "run_dir", "status", "env_steps", "total_steps", "wall_time_s", "checkpoints",
                "last_checkpoint", "success_rate", "curriculum_level_mean", "mean_episode_reward", "error")
TOKEN_FILE = ".hexbench-batch-token"  # in OUT while a batch runs: how a Ray task tells a shared filesystem
BATCH_OPTIONS = ("--terrain", "--seeds", "--seed", "--out", "--engine", "--address", "--parallel")


class BatchError(TrainError):
    """The batch cannot start, or some of its runs failed; the message is one line."""


def parse_seeds(text: str) -> tuple[int, ...]:
    """'0-4' -> (0, 1, 2, 3, 4); '0,2,5' and '0-2,7' too; sorted, each once."""
    seeds: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part[1:]:
                lo, hi = (int(p) for p in part.split("-", 1))
                if hi < lo:
                    raise ValueError
                seeds.update(range(lo, hi + 1))
            else:
                seeds.add(int(part))
        except ValueError:
            raise BatchError(f"--seeds {text!r} is not a list of seeds such as 0-4, 0,2,5 or 0-2,7") from None
    if not seeds or min(seeds) < 0:
        raise BatchError(f"--seeds {text!r}: seeds are integers >= 0")
    return tuple(sorted(seeds))


def parse_terrains(text: str) -> tuple[str, ...]:
    """'rough,slopes' -> ('rough', 'slopes'); each a training terrain."""
    terrains = tuple(dict.fromkeys(t.strip() for t in text.split(",") if t.strip()))
    bad = [t for t in terrains if t not in TRAIN_TERRAINS]
    if bad or not terrains:
        raise BatchError(f"unknown terrain {(bad or [text])[0]!r}; valid terrains: {', '.join(TRAIN_TERRAINS)} "
                         f"(comma-separated for several)")
    return terrains


def single_run_command(argv: list[str], terrain: str, seed: int, run_dir: Path) -> str:
    """The `hexbench train` command that trains (and resumes) one run of a batch started with `argv`
    (the arguments after `hexbench`): the batch's options, with --terrain T --seed S --out RUN_DIR
    in place of the batch's terrains, seeds, folder and engine."""
    import shlex

    kept, skip = [], False
    for token in argv:
        if skip:
            skip = False
            continue
        name = token.split("=", 1)[0]
        if name in BATCH_OPTIONS:
            skip = "=" not in token
            continue
        kept.append(token)
    return "hexbench " + shlex.join([*kept, "--terrain", terrain, "--seed", str(seed), "--out", str(run_dir)])


@dataclass(frozen=True)
class TrainBatch:
    """Every (terrain, seed) of `template` (its terrain, seed and out_dir are replaced per run)."""

    template: TrainSettings
    terrains: tuple[str, ...]
    seeds: tuple[int, ...]
    out_root: Path = Path("training")
    argv: tuple[str, ...] = ()  # the batch command's arguments, for each run's own command

    def runs(self) -> list[TrainSettings]:
        method = self.template.method
        out = []
        for terrain in self.terrains:
            for seed in self.seeds:
                run_dir = Path(self.out_root) / f"{method}-{terrain}-seed{seed}"
                command = single_run_command(list(self.argv), terrain, seed, run_dir) if self.argv else ""
                out.append(replace(self.template, terrain=terrain, seed=seed, out_dir=run_dir, command=command,
                                   show_progress=False, log_lines=False))
        return out

    @property
    def summary_path(self) -> Path:
        return Path(self.out_root) / f"{self.template.method}-runs.csv"


def check_batch(batch: TrainBatch) -> list[TrainSettings]:
    """The batch's runs, each checked as `hexbench train` checks one (a TrainError line for bad input)."""
    runs = batch.runs()
    for settings in runs:
        check_settings(settings)
        load_run_config(settings)
    return runs


def run_batch(batch: TrainBatch, engine, parallel: int | None = None, show_progress: bool = True) -> list[dict]:
    """Train every run of the batch on `engine` (a hexbench.evaluation.engines engine); write the
    summary CSV; return its rows. Settings are checked on the driver before anything runs."""
    runs = check_batch(batch)
    out_root = Path(batch.out_root)
    token = secrets.token_hex(16)
    try:
        out_root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise BatchError(f"{out_root}: cannot create the batch folder ({e.strerror})") from None
    write_text_atomic(out_root / TOKEN_FILE, token)
    cwd = os.getcwd()
    todo = [settings for settings in runs if not _finished(settings)]  # the driver's folders decide
    items = [(settings, cwd, str(out_root), token) for settings in todo]
    if parallel is None:
        parallel = len(runs) if engine.name != "local" else max(1, engine.default_workers() // runs[0].workers)
    resources = {"num_cpus": runs[0].workers, "num_gpus": 1 if runs[0].device == "cuda" else 0}
    watcher = _Progress(runs, show_progress, finished=len(runs) - len(todo))
    try:
        with watcher:
            results = engine.map(train_task, items, max(1, min(parallel, len(items))), watcher.run_done,
                                 resources=resources) if items else []
    finally:
        (out_root / TOKEN_FILE).unlink(missing_ok=True)
    errors: dict[Path, str | None] = {}
    for result in results:
        land_run_files(result)
        errors[Path(result["run_dir"])] = result.get("error")
    rows = [summary_row(settings, errors.get(Path(settings.run_dir))) for settings in runs]
    write_runs_csv(batch.summary_path, rows)
    return rows


def _finished(settings: TrainSettings) -> bool:
    """The run's folder holds this run at its whole budget (a batch run again leaves it as it is)."""
    from hexbench.agents.policy import config_dict
    from hexbench.training.runs import check_resume

    try:
        run = read_run(settings.run_dir)
        if run is None:
            return False
        check_resume(Path(settings.run_dir), run, settings, config_dict(load_run_config(settings)))
    except TrainError:
        return False  # another run, or a broken run.json: train() names the problem, as the run's error
    return int(run.get("env_steps") or 0) >= settings.total_steps


def train_task(item: tuple) -> dict:
    """One run of a batch, where the engine put it (this process, a pool worker, a Ray worker):
    train it, and hand its folder's files back when this node does not share the driver's files.
    A failure is returned as the run's one-line error, so the other runs go on."""
    from hexbench.errors import HexbenchError
    from hexbench.training.loop import train

    settings, cwd, out_root, token = item
    result: dict = {"run_dir": str(settings.run_dir), "error": None, "files": None}
    try:
        os.chdir(cwd)
    except OSError:
        import socket

        result["error"] = (f"the driver's working folder {cwd} does not exist on node {socket.gethostname()} "
                           f"(baseline files must be at the same path on every node)")
        return result
    shared = _reads_token(Path(out_root), token)
    try:
        train(settings)
    except HexbenchError as e:
        result["error"] = str(e)
    except Exception as e:  # noqa: BLE001 - a learner's crash fails this run only, in one line
        result["error"] = f"{type(e).__name__}: {' '.join(str(e).split())[:300]}"
    if not shared and Path(settings.run_dir).is_dir():
        result["files"] = {str(p.relative_to(settings.run_dir)): p.read_bytes()
                           for p in sorted(Path(settings.run_dir).rglob("*")) if p.is_file()}
    return result


def _reads_token(out_root: Path, token: str) -> bool:
    try:
        return (out_root / TOKEN_FILE).read_text() == token
    except OSError:
        return False


def land_run_files(result: dict) -> None:
    """Write the files a run shipped back (it ran where the driver's files are not) into its folder."""
    files = result.get("files")
    if not files:
        return
    run_dir = Path(result["run_dir"])
    for relative, data in files.items():
        target = run_dir / relative
        if run_dir.resolve() not in target.resolve().parents:
            raise BatchError(f"{run_dir}: a run shipped back a file outside its folder ({relative!r})")
        if not target.is_file() or target.read_bytes() != data:
            target.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomic(target, data)


def summary_row(settings: TrainSettings, error: str | None) -> dict:
    """A RUNS_COLUMNS row from the run's run.json (as it stands on the driver)."""
    try:
        run = read_run(settings.run_dir) or {}
    except TrainError as e:
        run, error = {}, error or str(e)
    last = (run.get("checkpoints") or [None])[-1] or {}
    env_steps = int(run.get("env_steps") or 0)
    status = "failed" if error else "done" if env_steps >= settings.total_steps else "incomplete"
    return {"terrain": settings.terrain, "seed": settings.seed, "run_dir": str(settings.run_dir), "status": status,
            "env_steps": env_steps, "total_steps": settings.total_steps, "wall_time_s": run.get("wall_time_s"),
            "checkpoints": len(run.get("checkpoints") or []), "last_checkpoint": last.get("file"),
            "success_rate": last.get("success_rate"), "curriculum_level_mean": last.get("curriculum_level_mean"),
            "mean_episode_reward": last.get("mean_episode_reward"), "error": error}


def write_runs_csv(path: Path, rows: list[dict]) -> None:
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=RUNS_COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: ("" if r.get(k) is None else r[k]) for k in RUNS_COLUMNS} for r in rows)


class _Progress:
    """A rich bar of the batch's env steps, read from the runs' run.json files every few seconds
    (where the driver sees them), and of the runs finished."""

    def __init__(self, runs: list[TrainSettings], show: bool, finished: int = 0, every_s: float = 5.0):
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.runs, self.every_s, self.finished = runs, every_s, finished
        self.progress = Progress(TextColumn(f"[bold]{runs[0].method} x {len(runs)} runs"), BarColumn(),
                                 MofNCompleteColumn(), TimeElapsedColumn(), TextColumn("{task.fields[info]}"),
                                 console=Console(stderr=True), disable=not show)
        self.task = self.progress.add_task("batch", total=sum(s.total_steps for s in runs), info="")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True, name="batch-progress")

    def __enter__(self):
        self.progress.start()
        self._update()
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(timeout=5)
        self._update()
        self.progress.stop()

    def run_done(self) -> None:
        self.finished += 1
        self._update()

    def _update(self) -> None:
        steps = 0
        for settings in self.runs:
            try:  # a run.json half-way through an atomic replace, or another run's: counted next time
                steps += min(int((read_run(settings.run_dir) or {}).get("env_steps") or 0), settings.total_steps)
            except (TrainError, OSError, ValueError, TypeError, AttributeError):
                continue
        self.progress.update(self.task, completed=steps, info=f"{self.finished}/{len(self.runs)} runs finished")

    def _poll(self) -> None:
        while not self._stop.wait(self.every_s):
            self._update()

