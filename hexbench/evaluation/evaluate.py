"""Run a controller file over protocol tasks: episodes in worker processes, resumable, records.

One episode is a function of (task, seed, controller file): `run_episode(EpisodeJob)` gets the
worker's sandboxed controller for the task (hexbench.evaluation.sandbox), plays the episode through the one
episode loop (hexbench.suite.rollout), writes its action log (always: OUT/episodes/<id>.actions, the
proof the record's row can be replayed from) and, when recording, its MCAP and .rrd, and returns
the outcome row. `evaluate(...)` fans episodes out over worker processes (each pinned to one core,
its controller process with it: the observation/action round trip is then a few microseconds),
journals each finished episode under OUT/.journal/ (only the evaluator writes there; a resumed run
re-checks every journal entry against its action log by replay before taking it), and at the end
writes OUT/episodes.parquet and OUT/result.json, each to a temporary name first. A controller that
misbehaves stops its run with one `ControllerError` line; the files this invocation wrote are
removed (never files it did not write), so no partial result remains.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from hexbench.artifacts.files import (
    atomic_path,
    check_writable,
    make_folder,
    read_bytes_bounded,
    sha256_file,
    write_text_atomic,
)
from hexbench.artifacts.provenance import HEXBENCH_VERSION, git_commit, machine_info
from hexbench.artifacts.records import episode_record_rows, episodes_digest, validate_record
from hexbench.errors import HexbenchError, InputError, OutputError, os_reason
from hexbench.evaluation import engines, sandbox
from hexbench.evaluation.episode import EpisodeJob, controller_changed, file_change, first_row_difference, replay_row
from hexbench.evaluation.isolation import seed_key_problem
from hexbench.suite.controller import MAX_CONTROLLER_FILE_BYTES, ControllerError, controller_file_problem
from hexbench.suite.scoring import summarize_levels, summarize_terrains
from hexbench.suite.seeds import SeedKeyError, SeedSet, run_secret
from hexbench.suite.tasks import TaskSpec

# ---------------------------------------------------------------------------------- records


def build_record(*, label: str, controller_file: str, action_mode: str, tasks: list[TaskSpec], rows: list[dict],
                 started_at: str, wall_time_s: float, workers: int, command: str, checkpoints: list[dict],
                 commit: str, isolation: dict | None = None, seed_set: dict | None = None,
                 engine: dict | None = None, controller_sha256: str | None = None) -> dict:
    units = {t.terrain: t.unit for t in tasks}
    headroom = {(t.terrain, t.level): t.headroom for t in tasks}
    episodes = episode_record_rows(rows)
    levels = summarize_levels(episodes, units, headroom)
    record = {
        "schema_version": 1,
        "protocol": tasks[0].protocol,
        "label": label,
        "kind": "measured",
        "controller": {"file": controller_file, "sha256": controller_sha256 or sha256_file(controller_file),
                       "action_mode": action_mode,
                       "checkpoints": checkpoints},
        "provenance": {"hexbench_version": HEXBENCH_VERSION, "git_commit": commit, "command": command,
                       "machine": machine_info(), "started_at": started_at, "wall_time_s": wall_time_s,
                       "workers": workers, "isolation": isolation or {"mode": "unknown", "sandboxed": False},
                       "seed_set": seed_set or {"kind": "public"},
                       "engine": engine or {"name": "local", "description": "local process pool"}},
        "levels": levels,
        "terrains": summarize_terrains(levels),
        "episodes": episodes,
        "episodes_digest": episodes_digest(episodes),
    }
    validate_record(record)
    return record


def run_time(timings) -> tuple[str, float]:
    """When a run began and how long it took, over every invocation that produced its episodes.

    `timings` holds (invocation id, its ISO start time, elapsed [s]) per journaled episode, plus one
    for the invocation finishing the run. A resumed run (killed, then run again with the same OUT)
    is made by several invocations: it began at the earliest start, and its wall time is the sum,
    over invocations, of the longest elapsed time each reached. Time an invocation spent after its
    last journaled episode (work lost to the kill) is not counted.
    """
    latest: dict[str, float] = {}
    starts: dict[str, str] = {}
    for invocation, started_at, elapsed_s in timings:
        latest[invocation] = max(latest.get(invocation, 0.0), elapsed_s)
        starts[invocation] = started_at
    return min(starts.values()), sum(latest.values())


# -------------------------------------------------------------------------------- the run
@dataclass
class RunResult:
    record: dict | None
    out_dir: Path
    error: str | None = None


def weights_by_terrain(controller_file: str, tasks: list[TaskSpec], isolation: str, limits,
                        hidden: tuple[str, ...], controller_sha256: str) -> dict[str, list[dict]]:
    """Per terrain, path and sha256 of every weights file the controller loads for it.

    A controller lists them in an optional `checkpoint_paths` attribute (the trained baselines
    do; the sandbox accepts only files in the controller's folder); one controller per terrain is
    built here, since baselines load per-terrain weights. Paths are shown relative to the
    controller's folder's parent when they lie under the working directory, else absolute.
    """
    used: dict[str, list[dict]] = {}
    for task in {t.terrain: t for t in reversed(tasks)}.values():
        ctrl = sandbox.controller_for(controller_file, task, isolation, limits, hidden, controller_sha256)
        files = {}
        for path in ctrl.checkpoint_paths:
            path = Path(path).resolve()
            try:
                shown = str(path.relative_to(Path.cwd()))
            except ValueError:
                shown = str(path)
            files[shown] = {"path": shown, "sha256": sha256_file(path, limits.address_space_bytes, "weights file")}
        used[task.terrain] = [files[k] for k in sorted(files)]
    return used


def _weights_changed(controller_file: str, weights: dict[str, list[dict]], limits) -> str | None:
    """Why a weights file the record names is no longer the one hashed when the run started, or None."""
    for entry in {w["path"]: w for ws in weights.values() for w in ws}.values():
        change = file_change(entry["path"], entry["sha256"], limits.address_space_bytes, "weights file")
        if change is not None:
            return f"{controller_file}: its weights file {entry['path']} {change}"
    return None


@dataclass
class _Journal:
    """OUT/.journal/: one entry per finished episode, written by the evaluator alone."""

    folder: Path
    out: Path
    controller_sha256: str
    weights: dict[str, list[dict]]
    seed_set: dict
    invocation: str
    started_at: str
    t0: float
    written: list[Path] = field(default_factory=list)

    def path(self, job: EpisodeJob) -> Path:
        return self.folder / f"{job.episode_id}.json"

    def resumable(self, job: EpisodeJob, record: bool, max_steps: int | None) -> tuple[dict, tuple] | None:
        """A journaled row for this job if it was made by the same controller, weights and seed set
        and its action log replays into it exactly; else None (the episode runs again)."""
        f = self.path(job)
        if not f.is_file():
            return None
        try:
            entry = json.loads(f.read_text())
            row = entry["row"]
            same = entry.get("controller_sha256") == self.controller_sha256 \
                and entry.get("protocol") == job.task.protocol and entry.get("seed_set") == self.seed_set \
                and sorted(w["sha256"] for w in entry.get("weights", [])) \
                == sorted(w["sha256"] for w in self.weights[job.task.terrain]) \
                and row["seed"] == job.seed and row["index"] == job.index and (not record or "mcap_path" in row)
            if not same:
                return None
            replayed = replay_row(job.task, row, self.out / "episodes", max_steps)
        except (ValueError, KeyError, TypeError, HexbenchError):
            return None
        if first_row_difference(row, replayed) is not None:
            return None
        return row, (entry["invocation"], entry["invocation_started_at"], entry["elapsed_s"])

    def add(self, job: EpisodeJob, row: dict) -> float:
        elapsed_s = time.perf_counter() - self.t0
        f = self.path(job)
        write_text_atomic(f, json.dumps({"controller_sha256": self.controller_sha256, "protocol": job.task.protocol,
                                         "seed_set": self.seed_set, "weights": self.weights[job.task.terrain],
                                         "invocation": self.invocation, "invocation_started_at": self.started_at,
                                         "elapsed_s": elapsed_s, "row": row}))
        self.written.append(f)
        for key in ("action_log_path", "mcap_path", "rrd_path"):
            if row.get(key):
                self.written.append(self.out / "episodes" / row[key])
        return elapsed_s


def _prepare_out(out: Path) -> list[Path]:
    """Make OUT, OUT/.journal (owner-only) and OUT/episodes; return the folders this call created
    (outermost first). One OutputError line for a read-only folder, a file in the way or a name too long."""
    try:
        created = [p for p in (out, out / ".journal", out / "episodes") if not p.exists()]
        is_file = out.exists() and not out.is_dir()
    except OSError as e:  # e.g. a name too long for the file system
        raise OutputError(f"{out}: cannot be used as the output folder ({os_reason(e)})") from None
    if is_file:
        raise OutputError(f"{out}: exists and is not a folder; choose another --out")
    make_folder(out / ".journal")
    make_folder(out / "episodes")
    try:
        (out / ".journal").chmod(0o700)
    except OSError as e:
        raise OutputError(f"{out}: cannot be written ({os_reason(e)})") from None
    check_writable(out)
    return created


def _remove_written(paths: list[Path], out: Path, created: list[Path]) -> None:
    """Remove the files this invocation wrote and the folders it created, never anything else."""
    for f in paths:
        try:
            f.unlink(missing_ok=True)
        except OSError:
            pass
    if out in created:
        shutil.rmtree(out, ignore_errors=True)
        return
    for folder in reversed(created):
        if folder == out / ".journal":  # made now, so its run secret is this invocation's too
            (folder / "run_secret").unlink(missing_ok=True)
        try:
            folder.rmdir()  # only if empty
        except OSError:
            pass


def evaluate(controller_file: str | Path, tasks: list[TaskSpec], out_dir: str | Path, *, episodes: int | None = None,
             workers: int = 1, record: bool = True, label: str | None = None, progress: bool = True,
             command: str | None = None, isolation: str = "auto", seed_set: SeedSet = SeedSet(),
             make_timeout_s: float = sandbox.DEFAULT_LIMITS.make_timeout_s, max_steps: int | None = None) -> RunResult:
    """Evaluate one controller file on `tasks`; see the module docstring."""
    controller_file = str(controller_file)
    out = Path(out_dir)
    label = label or Path(controller_file).stem
    command = command or " ".join(["hexbench"] + sys.argv[1:])
    mode = sandbox.resolve_isolation(isolation)
    limits = sandbox.Limits(make_timeout_s=make_timeout_s)
    problem = controller_file_problem(controller_file)
    if problem:
        raise ControllerError(problem)
    key_problem = seed_key_problem(mode, controller_file, seed_set.source if seed_set.key is not None else None)
    if key_problem:
        raise SeedKeyError(key_problem)
    created = _prepare_out(out)
    written: list[Path] = []
    try:
        return _evaluate(controller_file, tasks, out, episodes, workers, record, label, progress, command, mode, limits,
                         seed_set, max_steps, written)
    except HexbenchError as e:
        _remove_written(written, out, created)
        return RunResult(None, out, str(e))
    finally:
        sandbox.close_all()


def _evaluate(controller_file, tasks, out, episodes, workers, record, label, progress, command, mode, limits, seed_set,
              max_steps, written) -> RunResult:
    # Built once here: a file that fails to import or build fails before any worker starts.
    # the journal (run secret) and the logs are hidden from the controller, and so is a seed key
    hidden = tuple(str(p) for p in (out.resolve() / ".journal", out.resolve() / "episodes", seed_set.source)
                   if p is not None)
    # the code the record names: every episode checks it is still this file (`controller_changed`)
    started_sha256 = sha256_file(controller_file, MAX_CONTROLLER_FILE_BYTES, "controller file")
    weights = weights_by_terrain(controller_file, tasks, mode, limits, hidden, started_sha256)
    action_mode = sandbox.controller_for(controller_file, tasks[0], mode, limits, hidden, started_sha256).action_mode
    if workers > 1:
        sandbox.close_all()  # the workers start their own controller processes
    checkpoints = sorted({w["path"]: w for ws in weights.values() for w in ws}.values(), key=lambda w: w["path"])
    secret = run_secret(out / ".journal")
    started_at = datetime.now(timezone.utc).isoformat(timespec="seconds")
    journal = _Journal(out / ".journal", out, started_sha256, weights, seed_set.record(),
                       f"{started_at}/{os.getpid()}", started_at, time.perf_counter(), written)
    record_dir = str(out / "episodes") if record else None
    jobs = [EpisodeJob(controller_file, t, i, s, record_dir, max_steps=max_steps, log_dir=str(out / "episodes"),
                       isolation=mode, secret_hex=secret.hex(), make_timeout_s=limits.make_timeout_s, hidden=hidden,
                       controller_sha256=started_sha256)
            for t in tasks for i, s in enumerate(seed_set.seeds(t, episodes))]
    done: dict[str, dict] = {}
    timing: dict[str, tuple[str, str, float]] = {}  # episode id -> (invocation, its start, elapsed [s] at journaling)
    for job in jobs:
        resumed = journal.resumable(job, record, max_steps)
        if resumed is not None:
            done[job.episode_id], timing[job.episode_id] = resumed
    todo = [j for j in jobs if j.episode_id not in done]
    commit = git_commit()  # the code that runs, taken before the first episode

    def finished(job: EpisodeJob, row: dict) -> None:
        elapsed_s = journal.add(job, row)
        done[job.episode_id] = row
        timing[job.episode_id] = (journal.invocation, started_at, elapsed_s)

    engine = engines.current()
    engine_record = {"name": engine.name, "description": engine.describe()}  # where the run started (nodes may leave)
    _play_all(engine, todo, len(jobs), workers, label, progress, finished)
    problem = controller_changed(controller_file, started_sha256) or _weights_changed(controller_file, weights, limits)
    if problem:
        raise ControllerError(problem)
    rows = [done[j.episode_id] for j in jobs]
    run_started_at, wall_time_s = run_time([*timing.values(), (journal.invocation, started_at,
                                                               time.perf_counter() - journal.t0)])
    rec = build_record(label=label, controller_file=controller_file, action_mode=action_mode, tasks=tasks, rows=rows,
                       started_at=run_started_at, wall_time_s=wall_time_s, workers=workers, command=command,
                       checkpoints=checkpoints, commit=commit, isolation=sandbox.isolation_record(mode, limits, controller_file),
                       seed_set=seed_set.record(), engine=engine_record, controller_sha256=started_sha256)
    import pandas as pd

    ordered = sorted(jobs, key=lambda j: (j.task.terrain, j.task.level, j.index))
    table = pd.DataFrame([{"episode_id": j.episode_id, **done[j.episode_id]} for j in ordered])
    with atomic_path(out / "episodes.parquet") as tmp:
        table.to_parquet(tmp, index=False)
    write_text_atomic(out / "result.json", json.dumps(rec, indent=1, sort_keys=False) + "\n")
    return RunResult(rec, out)


# The episode index of a run (OUT/episodes.parquet): a full protocol v1 run's has 860 rows, 0.27 MB on
# disk and 0.33 MB uncompressed. Run folders travel, and Parquet's run-length and dictionary encodings
# let a small file stand for billions of rows, so a reader checks the metadata before decoding: at most
# MAX_EPISODE_INDEX_ROWS rows and MAX_EPISODE_INDEX_UNCOMPRESSED_BYTES declared, string columns read as
# dictionaries (a value repeated on every row is held once).
MAX_EPISODE_INDEX_BYTES = 64 << 20
MAX_EPISODE_INDEX_UNCOMPRESSED_BYTES = 256 << 20
MAX_EPISODE_INDEX_ROWS = 100_000


def read_episode_index(path: Path):
    """A run's episode index (episodes.parquet) as a DataFrame; InputError (one line) if it is not a
    plain file within MAX_EPISODE_INDEX_BYTES, its metadata declares more than MAX_EPISODE_INDEX_ROWS
    rows or MAX_EPISODE_INDEX_UNCOMPRESSED_BYTES, or it is not a readable Parquet file."""
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    data = read_bytes_bounded(path, MAX_EPISODE_INDEX_BYTES, "episode index")
    try:
        index = pq.ParquetFile(io.BytesIO(data))
        meta = index.metadata
        declared = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
        if meta.num_rows > MAX_EPISODE_INDEX_ROWS or declared > MAX_EPISODE_INDEX_UNCOMPRESSED_BYTES:
            raise InputError(f"{path}: declares {meta.num_rows:,} rows and {declared:,} bytes uncompressed; an episode "
                             f"index holds at most {MAX_EPISODE_INDEX_ROWS:,} rows and "
                             f"{MAX_EPISODE_INDEX_UNCOMPRESSED_BYTES:,} bytes")
        strings = [f.name for f in index.schema_arrow if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)]
        table = pq.read_table(io.BytesIO(data), read_dictionary=strings).to_pandas()
        return table.astype({name: object for name in strings})
    except (OSError, ValueError) as e:  # pyarrow's errors for a damaged file are OSErrors and ValueErrors
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(f"{path}: unreadable episode index ({reason})") from None


def _play_all(engine, todo: list[EpisodeJob], total: int, workers: int, label: str, progress: bool, finished) -> None:
    """Play every job on `engine` (the one chosen with `hexbench.evaluation.engines.using`, else
    the local pool of `workers` pinned processes), with a progress bar, calling `finished(job, row)`
    as each ends; the first ControllerError stops the rest and propagates."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(TextColumn(f"[bold]{label}[/]"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TimeRemainingColumn(), disable=not progress, transient=False) as bar:
        task_bar = bar.add_task("episodes", total=total, completed=total - len(todo))
        if todo:
            engine.play_all(todo, finished, lambda: bar.advance(task_bar), workers)
