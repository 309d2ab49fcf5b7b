"""Run a controller file over protocol tasks: episodes in worker processes, resumable, records.

One episode is a function of (task, seed, controller file): `run_episode(EpisodeJob)` gets the
worker's sandboxed controller for the task (hexbench.sandbox), plays the episode through the one
episode loop (hexbench.rollout), writes its action log (always: OUT/episodes/<id>.actions, the
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
import platform
import shutil
import socket
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from datetime import datetime, timezone
from multiprocessing import get_context
from pathlib import Path

import hexbench
from hexbench import action_log, sandbox
from hexbench.controller import ControllerError
from hexbench.errors import HexbenchError, OutputError
from hexbench.files import make_folder, os_reason, sha256_file, write_text_atomic
from hexbench.records import episode_record_rows, episodes_digest
from hexbench.rollout import ROW_FIELDS, LoggedActions, play
from hexbench.scoring import summarize_levels, summarize_terrains
from hexbench.seeds import SeedSet, controller_seed, run_secret
from hexbench.tasks import TaskSpec, format_level

ACT_TIMEOUT_S = sandbox.DEFAULT_LIMITS.call_timeout_s  # protocol v1: one act() call may take at most this long [s]
RESULT_SCHEMA = Path(__file__).parent / "schemas" / "result.schema.json"
file_sha256 = sha256_file


@dataclass(frozen=True)
class EpisodeJob:
    controller_file: str
    task: TaskSpec
    index: int
    seed: int
    record_dir: str | None = None  # where MCAP/.rrd logs go; None: no recording
    act_timeout_s: float = ACT_TIMEOUT_S
    max_steps: int | None = None  # override (hexbench check); None: the task's limit
    log_dir: str | None = None  # where the action log goes (OUT/episodes); None: not written
    isolation: str = "bubblewrap"
    secret_hex: str = ""  # the run secret controller seeds are derived from ("" : a fixed one, for checks)
    make_timeout_s: float = sandbox.DEFAULT_LIMITS.make_timeout_s
    hidden: tuple[str, ...] = ()  # paths the controller must never see (the run folder, a seed key)

    @property
    def episode_id(self) -> str:
        return f"{self.task.terrain}-{format_level(self.task.level)}{self.task.unit}-{self.index:02d}"

    @property
    def limits(self) -> sandbox.Limits:
        return sandbox.Limits(call_timeout_s=self.act_timeout_s, make_timeout_s=self.make_timeout_s)


def _make_recorder(job: EpisodeJob, action_mode: str):
    if job.record_dir is None:
        return None
    from hexbench.recording import make_episode_recorder

    meta = {
        "episode_id": job.episode_id, "protocol": job.task.protocol, "terrain": job.task.terrain,
        "level": job.task.level, "unit": job.task.unit, "index": job.index, "seed": job.seed,
        "action_mode": action_mode, "controller_file": job.controller_file,
        "controller_sha256": file_sha256(job.controller_file), "hexbench_version": hexbench.__version__,
    }
    return make_episode_recorder(Path(job.record_dir), job.episode_id, meta)


def run_episode(job: EpisodeJob) -> dict:
    """Play one episode; return its outcome row. Raises ControllerError for a bad controller."""
    actor = sandbox.controller_for(job.controller_file, job.task, job.isolation, job.limits, job.hidden)
    recorder = _make_recorder(job, actor.action_mode)
    secret = bytes.fromhex(job.secret_hex) if job.secret_hex else b"hexbench-check"
    try:
        episode = play(job.task, job.seed, actor, index=job.index, controller_seed=controller_seed(secret, job.seed),
                       recorder=recorder, max_steps=job.max_steps, where=job.controller_file)
        row = episode.row
        if job.log_dir is not None:
            log = action_log.ActionLog(job.task.protocol, job.task.terrain, job.task.level, job.index, job.seed,
                                       actor.action_mode, episode.actions)
            name = job.episode_id + action_log.SUFFIX
            make_folder(Path(job.log_dir))
            row["action_log_path"] = name
            row["action_log_sha256"] = action_log.write(Path(job.log_dir) / name, log)
        if recorder is not None:
            row.update(recorder.on_end(row))
            recorder = None
        return row
    finally:
        if recorder is not None:
            recorder.abort()


def replay_row(task: TaskSpec, row: dict, log_dir: Path, max_steps: int | None = None) -> dict:
    """Re-simulate an episode row from its action log alone; return the replayed row.

    Raises ActionLogError (missing, corrupt, or sha256 differs from the row) or ReplayMismatch.
    """
    where = str(log_dir / str(row.get("action_log_path", "?")))
    if not row.get("action_log_path") or not row.get("action_log_sha256"):
        raise action_log.ActionLogError(f"{task.name} episode {row.get('index')}: the row names no action log")
    log = action_log.read(log_dir / str(row["action_log_path"]), row["action_log_sha256"])
    if (log.terrain, float(log.level), log.index, log.seed) != (task.terrain, float(task.level), row["index"], row["seed"]):
        raise action_log.ActionLogError(f"{where}: the action log belongs to another episode "
                                        f"({log.terrain} {log.level:g} #{log.index}, seed {log.seed})")
    return play(task, int(row["seed"]), LoggedActions(log, where), index=int(row["index"]), max_steps=max_steps,
                where=where).row


def first_row_difference(stored: dict, replayed: dict) -> str | None:
    """The first outcome field in which a stored row and its replay differ (exact: the physics is deterministic)."""
    for key in ROW_FIELDS:
        if stored.get(key) != replayed.get(key):
            return f"{key}: recorded {stored.get(key)!r}, replayed {replayed.get(key)!r}"
    return None


def _exit_when_orphaned(parent_pid: int, poll_s: float = 1.0) -> None:
    """Worker-side watchdog: exit as soon as the evaluating process is gone (killed by SIGTERM or
    SIGKILL, it cannot shut its pool down; without this its spawn workers would wait forever)."""
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(1)


def _worker_init(parent_pid: int, next_core=None) -> None:
    import threading
    from multiprocessing import util

    threading.Thread(target=_exit_when_orphaned, args=(parent_pid,), daemon=True, name="orphan-watchdog").start()
    util.Finalize(None, sandbox.close_all, exitpriority=10)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if next_core is not None:
        with next_core.get_lock():
            slot = next_core.value
            next_core.value += 1
        pin_to_core(slot)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass


def pin_to_core(slot: int | None = None) -> set[int] | None:
    """Pin this process (and the controller processes it starts) to one core of its allowed set:
    the `slot`-th, or (None) the one it runs on now, so that single-worker runs started side by
    side do not pile onto one core. Returns the previous set. Evaluator and controller then share
    a core: they never run at once, and a round trip on one core costs a few microseconds instead
    of tens across cores."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    core = allowed[slot % len(allowed)] if slot is not None else _current_cpu(allowed)
    os.sched_setaffinity(0, {core})
    return set(allowed)


def _current_cpu(allowed: list[int]) -> int:
    """The CPU this process last ran on (/proc/self/stat field 39), if it is allowed."""
    try:
        cpu = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[36])
    except (OSError, ValueError, IndexError):
        return allowed[0]
    return cpu if cpu in allowed else allowed[0]


# ---------------------------------------------------------------------------------- records
def git_commit() -> str:
    root = Path(__file__).resolve().parent.parent
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, timeout=10)
        if sha.returncode == 0:
            return sha.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return "unknown"


# Packages whose arithmetic an episode's outcome depends on. The physics reproduces bit for bit on
# another x86 machine, a policy's float32 forward pass need not (docs/training.md, session 11).
OUTCOME_PACKAGES: tuple[str, ...] = ("numpy", "pybullet", "torch")


def cpu_model() -> str:
    """The processor's model name (/proc/cpuinfo on Linux), else what `platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def package_versions(names: tuple[str, ...] = OUTCOME_PACKAGES) -> dict[str, str | None]:
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str | None] = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


def machine_info() -> dict:
    return {"hostname": socket.gethostname(), "platform": platform.platform(), "python": platform.python_version(),
            "cpu_count": os.cpu_count(), "cpu_model": cpu_model(), "packages": package_versions()}


def validate_record(record: dict) -> None:
    import jsonschema

    jsonschema.validate(record, json.loads(RESULT_SCHEMA.read_text()))


def build_record(*, label: str, controller_file: str, action_mode: str, tasks: list[TaskSpec], rows: list[dict],
                 started_at: str, wall_time_s: float, workers: int, command: str, checkpoints: list[dict],
                 commit: str, isolation: dict | None = None, seed_set: dict | None = None) -> dict:
    units = {t.terrain: t.unit for t in tasks}
    headroom = {(t.terrain, t.level): t.headroom for t in tasks}
    episodes = episode_record_rows(rows)
    levels = summarize_levels(episodes, units, headroom)
    record = {
        "schema_version": 1,
        "protocol": tasks[0].protocol,
        "label": label,
        "kind": "measured",
        "controller": {"file": controller_file, "sha256": file_sha256(controller_file), "action_mode": action_mode,
                       "checkpoints": checkpoints},
        "provenance": {"hexbench_version": hexbench.__version__, "git_commit": commit, "command": command,
                       "machine": machine_info(), "started_at": started_at, "wall_time_s": wall_time_s,
                       "workers": workers, "isolation": isolation or {"mode": "unknown", "sandboxed": False},
                       "seed_set": seed_set or {"kind": "public"}},
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


def _weights_by_terrain(controller_file: str, tasks: list[TaskSpec], isolation: str, limits,
                        hidden: tuple[str, ...]) -> dict[str, list[dict]]:
    """Per terrain, path and sha256 of every weights file the controller loads for it.

    A controller lists them in an optional `checkpoint_paths` attribute (the trained baselines
    do; the sandbox accepts only files in the controller's folder); one controller per terrain is
    built here, since baselines load per-terrain weights. Paths are shown relative to the
    controller's folder's parent when they lie under the working directory, else absolute.
    """
    used: dict[str, list[dict]] = {}
    for task in {t.terrain: t for t in reversed(tasks)}.values():
        ctrl = sandbox.controller_for(controller_file, task, isolation, limits, hidden)
        files = {}
        for path in ctrl.checkpoint_paths:
            path = Path(path).resolve()
            try:
                shown = str(path.relative_to(Path.cwd()))
            except ValueError:
                shown = str(path)
            files[shown] = {"path": shown, "sha256": file_sha256(path)}
        used[task.terrain] = [files[k] for k in sorted(files)]
    return used


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
        probe = out / f".write-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise OutputError(f"{out}: cannot be written ({os_reason(e)})") from None
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
    if not Path(controller_file).is_file():
        raise ControllerError(f"{controller_file}: no such controller file")
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
    weights = _weights_by_terrain(controller_file, tasks, mode, limits, hidden)
    action_mode = sandbox.controller_for(controller_file, tasks[0], mode, limits, hidden).action_mode
    if workers > 1:
        sandbox.close_all()  # the workers start their own controller processes
    checkpoints = sorted({w["path"]: w for ws in weights.values() for w in ws}.values(), key=lambda w: w["path"])
    secret = run_secret(out / ".journal")
    started_at = datetime.now(timezone.utc).isoformat(timespec="seconds")
    journal = _Journal(out / ".journal", out, file_sha256(controller_file), weights, seed_set.record(),
                       f"{started_at}/{os.getpid()}", started_at, time.perf_counter(), written)
    record_dir = str(out / "episodes") if record else None
    jobs = [EpisodeJob(controller_file, t, i, s, record_dir, max_steps=max_steps, log_dir=str(out / "episodes"),
                       isolation=mode, secret_hex=secret.hex(), make_timeout_s=limits.make_timeout_s, hidden=hidden)
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

    _play_all(todo, len(jobs), workers, label, progress, finished)
    rows = [done[j.episode_id] for j in jobs]
    run_started_at, wall_time_s = run_time([*timing.values(), (journal.invocation, started_at,
                                                               time.perf_counter() - journal.t0)])
    rec = build_record(label=label, controller_file=controller_file, action_mode=action_mode, tasks=tasks, rows=rows,
                       started_at=run_started_at, wall_time_s=wall_time_s, workers=workers, command=command,
                       checkpoints=checkpoints, commit=commit, isolation=sandbox.isolation_record(mode, limits, controller_file),
                       seed_set=seed_set.record())
    import pandas as pd

    ordered = sorted(jobs, key=lambda j: (j.task.terrain, j.task.level, j.index))
    table = pd.DataFrame([{"episode_id": j.episode_id, **done[j.episode_id]} for j in ordered])
    tmp = out / f".episodes.parquet.{os.getpid()}.tmp"
    try:
        table.to_parquet(tmp, index=False)
        os.replace(tmp, out / "episodes.parquet")
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"{out / 'episodes.parquet'}: cannot be written ({os_reason(e)})") from None
    write_text_atomic(out / "result.json", json.dumps(rec, indent=1, sort_keys=False) + "\n")
    return RunResult(rec, out)


def _play_all(todo: list[EpisodeJob], total: int, workers: int, label: str, progress: bool, finished) -> None:
    """Play every job (in this process, over a pool of `workers` pinned processes, or as tasks of
    the engine chosen with `hexbench.engines.using`, e.g. a Ray cluster), calling
    `finished(job, row)` as each ends; the first ControllerError stops the rest and propagates."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from hexbench import engines

    engine = engines.current()
    with Progress(TextColumn(f"[bold]{label}[/]"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TimeRemainingColumn(), disable=not progress, transient=False) as bar:
        task_bar = bar.add_task("episodes", total=total, completed=total - len(todo))
        if engine is not None and engine.name != "local":
            if todo:
                engine.play_all(todo, finished, lambda: bar.advance(task_bar), workers)
            return
        if workers <= 1:
            previous = pin_to_core()
            try:
                for job in todo:
                    finished(job, run_episode(job))
                    bar.advance(task_bar)
            finally:
                if previous is not None:
                    os.sched_setaffinity(0, previous)
            return
        ctx = get_context("spawn")
        next_core = ctx.Value("i", 0)
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                                 initargs=(os.getpid(), next_core)) as pool:
            futures = {pool.submit(run_episode, job): job for job in todo}
            pending = set(futures)
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in done:
                        exc = fut.exception()
                        if exc is not None:
                            if not isinstance(exc, HexbenchError):
                                exc = ControllerError(f"{futures[fut].controller_file}: its episode "
                                                      f"{futures[fut].episode_id} failed in a worker: "
                                                      f"{type(exc).__name__}: {exc}")
                            raise exc
                        finished(futures[fut], fut.result())
                        bar.advance(task_bar)
            finally:
                for p in pending:
                    p.cancel()
