"""`hexbench verify RUN_DIR --rerun`: play a record's episodes again with the controller it names,
sandboxed, and compare every action with the record's action logs.

Replay (`hexbench.replay.verify`) proves that a record's actions make its outcomes, never who chose
those actions: a record's `isolation` is its maker's word, and action logs could come from
anywhere (an optimiser that knew the public episodes, say). Re-running the controller file the
record names (the same sha256, the same weights) in this machine's sandbox on the record's episode
seeds must give the same float32 action at every control step: the controller's math is pinned
(`hexbench.suite.numerics`), and the shipped baselines' records reproduce across machines bit for
bit. A controller's `reset()` seed comes from the run's secret (`OUT/.journal/run_secret`), used
where the run folder holds it; without it only controllers whose actions do not depend on that
seed can reproduce, which the report says.

The run folder's record, episode index, action logs and journal are hidden from the controller
(it could otherwise read the recorded actions back), so a re-run needs a sandbox that hides files:
bubblewrap, or process isolation with Landlock. The first episode whose actions differ is named,
with the first step where they do.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.artifacts import action_log
from hexbench.artifacts.files import read_bytes_bounded, sha256_file
from hexbench.errors import HexbenchError, InputError
from hexbench.evaluation import engines, sandbox
from hexbench.evaluation.episode import EpisodeJob, first_row_difference
from hexbench.evaluation.evaluate import weights_by_terrain
from hexbench.evaluation.isolation import landlock_abi
from hexbench.replay.verify import episode_name
from hexbench.suite.controller import MAX_CONTROLLER_FILE_BYTES
from hexbench.suite.seeds import RUN_SECRET_FILE
from hexbench.suite.tasks import load_suite

RUN_SECRET_BYTES = 32


class RerunError(HexbenchError):
    """A record's controller cannot be re-run here (not the recorded file or weights, no sandbox that hides files)."""


@dataclass(frozen=True)
class RerunReport:
    ok: bool
    message: str
    episodes_rerun: int
    isolation: str = ""  # the sandbox the controller ran in
    with_run_secret: bool = False  # whether its reset() seeds came from the run's secret


def read_run_secret_hex(run_dir: Path) -> str | None:
    """The run's secret as hex (what its controllers' reset() seeds came from), or None where the run
    folder does not hold a readable one."""
    path = run_dir / ".journal" / RUN_SECRET_FILE
    try:
        text = read_bytes_bounded(path, 4 * RUN_SECRET_BYTES, "run secret").decode("ascii").strip()
        return bytes.fromhex(text).hex() if text else None
    except (InputError, OSError, UnicodeDecodeError, ValueError):
        return None


def first_action_difference(recorded: np.ndarray, rerun: np.ndarray) -> str:
    """Where two episodes' action sequences part: the first step that differs and by how much."""
    common = min(len(recorded), len(rerun))
    differs = np.flatnonzero(np.any(recorded[:common].view(np.uint32) != rerun[:common].view(np.uint32), axis=1))
    if len(differs) == 0:
        return f"the same actions for {common} steps, then the record ends after {len(recorded)}, the re-run after {len(rerun)}"
    step = int(differs[0])
    gap = float(np.max(np.abs(recorded[step].astype(np.float64) - rerun[step].astype(np.float64))))
    return f"the actions differ from step {step} on (max |difference| {gap:.3g} there)"


def _hidden_paths(run_dir: Path) -> tuple[str, ...]:
    """What of the run folder the controller must not see: everything that holds its actions or outcomes."""
    folder = run_dir.resolve()
    return tuple(str(folder / name) for name in ("result.json", "episodes.parquet", "episodes", ".journal")
                 if (folder / name).exists())


def rerun_episodes(run_dir: str | Path, record: dict, rows: list[dict], controller_file: str | Path, *,
                   isolation: str = "auto", workers: int = 1, progress: bool = False) -> RerunReport:
    """Play `rows` (episodes of `record`, the run in `run_dir`) again with `controller_file`, sandboxed;
    RerunReport(ok) if every action of every episode is the recorded one. RerunError (one line) if
    the file or its weights are not the recorded ones, or no sandbox here can hide the run folder."""
    run_dir = Path(run_dir)
    controller_file = str(controller_file)
    named = record["controller"]
    sha = sha256_file(controller_file, MAX_CONTROLLER_FILE_BYTES, "controller file")
    if sha != named["sha256"]:
        raise RerunError(f"{controller_file}: is not the controller the record names ({named['file']}, sha256 "
                         f"{named['sha256'][:12]}; this file's is {sha[:12]})")
    mode = sandbox.resolve_isolation(isolation)
    if not (mode == "bubblewrap" or (mode == "process" and landlock_abi())):
        raise RerunError(f"{controller_file}: re-running needs a sandbox that hides the run folder from the controller "
                         f"(bubblewrap, or --isolation process where the kernel has Landlock); here: {mode}")
    suite = load_suite(record["protocol"])
    tasks = {(t.terrain, float(t.level)): t for t in suite.all_tasks}
    secret_hex = read_run_secret_hex(run_dir)
    results: dict[tuple, dict] = {}
    with tempfile.TemporaryDirectory(prefix="hexbench-rerun-") as scratch:
        hidden = (*_hidden_paths(run_dir), scratch)
        try:
            _check_weights(controller_file, named, [tasks[(r["terrain"], float(r["level"]))] for r in rows], mode,
                           hidden, sha)
            if workers > 1:
                sandbox.close_all()  # the workers start their own controller processes; one worker reuses it
            jobs = [EpisodeJob(controller_file, tasks[(r["terrain"], float(r["level"]))], int(r["index"]),
                               int(r["seed"]), log_dir=scratch, isolation=mode, secret_hex=secret_hex or "",
                               hidden=hidden, controller_sha256=sha)
                    for r in rows]

            def finished(job: EpisodeJob, row: dict) -> None:
                results[(job.task.terrain, float(job.task.level), job.index)] = row

            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            with Progress(TextColumn("[bold]re-running[/]"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                          disable=not progress) as bar:
                task_bar = bar.add_task("episodes", total=len(jobs))
                engines.current().play_all(jobs, finished, lambda: bar.advance(task_bar), workers)
        finally:
            sandbox.close_all()
        for row in rows:
            key = (row["terrain"], float(row["level"]), int(row["index"]))
            problem = _difference(run_dir, row, results[key], Path(scratch), tasks[key[:2]].unit)
            if problem:
                hint = "" if secret_hex else (" (the run folder holds no run secret, .journal/run_secret: a controller "
                                              "whose actions depend on its reset() seed cannot be reproduced without it)")
                return RerunReport(False, f"{run_dir}: {problem}{hint}", len(results), mode, secret_hex is not None)
    seeds = "with the run's secret" if secret_hex else "without the run's secret"
    total = len(record["episodes"])
    what = f"{len(rows)} of {total} episodes" if len(rows) < total else "the episode" if total == 1 else f"all {total} episodes"
    return RerunReport(True, f"{run_dir}: {controller_file} (sha256 {sha[:12]}, its weights as recorded), re-run "
                             f"under {mode} isolation {seeds}, chose every action of {what} exactly as recorded, and "
                             f"every row came out as recorded",
                       len(results), mode, secret_hex is not None)


def _check_weights(controller_file: str, named: dict, tasks: list, mode: str, hidden: tuple[str, ...],
                   sha: str) -> None:
    """RerunError unless every weights file the controller declares for `tasks` is one the record names."""
    chosen = list({(t.terrain, float(t.level)): t for t in tasks}.values())
    weights = weights_by_terrain(controller_file, chosen, mode, sandbox.Limits(), hidden, sha)
    recorded = {w["sha256"] for w in named.get("checkpoints", [])}
    other = sorted({w["path"] for ws in weights.values() for w in ws if w["sha256"] not in recorded})
    if other:
        raise RerunError(f"{controller_file}: its weights file {other[0]} is not one the record names (sha256 differs): "
                         f"the re-run would not be the recorded controller")


def _difference(run_dir: Path, recorded: dict, rerun: dict, scratch: Path, unit: str) -> str | None:
    name = episode_name(recorded, unit)
    if rerun.get("action_log_sha256") == recorded.get("action_log_sha256"):
        diff = first_row_difference(recorded, rerun)  # the same actions replay the same: only a forged row differs
        return None if diff is None else f"{name}: {diff}"
    try:
        mine = action_log.read(scratch / rerun["action_log_path"], rerun["action_log_sha256"]).actions
        theirs = action_log.read(run_dir / "episodes" / str(recorded.get("action_log_path")),
                                 recorded.get("action_log_sha256")).actions
    except action_log.ActionLogError as e:
        return f"{name}: the re-run's actions differ from the record's, whose log cannot be read ({e})"
    return f"{name}: {first_action_difference(theirs, mine)}"


__all__ = ["RerunError", "RerunReport", "first_action_difference", "read_run_secret_hex", "rerun_episodes"]
