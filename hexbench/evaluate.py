"""Run a controller file over protocol tasks: episodes in worker processes, resumable, records.

One episode is a pure function of (task, seed, controller file): `run_episode(EpisodeJob)`
builds a fresh environment and controller, plays until the episode ends and returns its
outcome row (and, when recording, its log files). `evaluate(...)` fans episodes out over
worker processes, journals each finished episode under OUT/.journal/ (so a re-run with the
same OUT skips it), and at the end writes OUT/episodes.parquet and OUT/result.json, each to a
temporary name first. A resumed run's record counts the wall time of every invocation that
produced its episodes (`run_time`). A controller that misbehaves stops its run with a `ControllerError`;
the run's journal entries are removed so no partial result remains.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
import signal
import socket
import subprocess
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from multiprocessing import get_context
from pathlib import Path

import numpy as np

import hexbench
from hexbench.controller import ControllerError, check_action, file_sha256, make_controller
from hexbench.env import HexapodEnv
from hexbench.scoring import summarize_levels, summarize_terrains
from hexbench.tasks import TaskSpec, format_level

ACT_TIMEOUT_S = 1.0  # protocol v1: one act() call may take at most this long [s]
RESULT_SCHEMA = Path(__file__).parent / "schemas" / "result.schema.json"


@dataclass(frozen=True)
class EpisodeJob:
    controller_file: str
    task: TaskSpec
    index: int
    seed: int
    record_dir: str | None = None  # where episode logs go; None: no recording
    act_timeout_s: float = ACT_TIMEOUT_S
    max_steps: int | None = None  # override (hexbench check); None: the task's limit

    @property
    def episode_id(self) -> str:
        return f"{self.task.terrain}-{format_level(self.task.level)}{self.task.unit}-{self.index:02d}"


class _ActTimeout(Exception):
    pass


@contextmanager
def _time_limit(seconds: float):
    """Raise _ActTimeout if the block runs longer than `seconds` (main thread, Unix)."""
    if seconds <= 0 or not hasattr(signal, "setitimer"):
        yield
        return

    def _raise(signum, frame):
        raise _ActTimeout()

    old = signal.signal(signal.SIGALRM, _raise)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


_CONTROLLERS: dict[tuple[str, str, TaskSpec], object] = {}


def _controller_for(job: EpisodeJob):
    """One controller per (file content, task) per process, built on first use."""
    key = (job.controller_file, file_sha256(job.controller_file), job.task)
    if key not in _CONTROLLERS:
        _CONTROLLERS[key] = make_controller(job.controller_file, job.task)
    return _CONTROLLERS[key]


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
    ctrl = _controller_for(job)
    where = f"{job.controller_file}"
    mode = ctrl.action_mode
    cfg = job.task.env_config(mode)
    if job.max_steps is not None:
        from dataclasses import replace

        cfg = replace(cfg, max_steps=job.max_steps)
    env = HexapodEnv(cfg)
    recorder = None
    try:
        obs, _ = env.reset(seed=job.seed)
        recorder = _make_recorder(job, mode)
        if recorder is not None:
            recorder.on_reset(env)
        try:
            with _time_limit(job.act_timeout_s):
                ctrl.reset(job.seed)
        except _ActTimeout:
            raise ControllerError(f"{where}: reset() took longer than {job.act_timeout_s:g} s") from None
        except ControllerError:
            raise
        except BaseException as e:  # noqa: BLE001
            raise ControllerError(f"{where}: reset() raised {type(e).__name__}: {e}") from None
        see = _camera_channel(ctrl, env, where, job.act_timeout_s)
        dim = env.action_space.shape[0]
        dt = cfg.physics.control_dt_s
        rolls, pitches = [], []
        energy_j = 0.0
        max_abs_y = 0.0
        time_to_goal = None
        step = 0
        while True:
            if see is not None:
                see(step)
            try:
                with _time_limit(job.act_timeout_s):
                    action = ctrl.act(obs.copy())
            except _ActTimeout:
                raise ControllerError(f"{where}: act() took longer than {job.act_timeout_s:g} s at step {step}") from None
            except BaseException as e:  # noqa: BLE001
                raise ControllerError(f"{where}: act() raised {type(e).__name__} at step {step}: {e}") from None
            action = check_action(action, dim, f"{where}: step {step}")
            obs, reward, terminated, truncated, info = env.step(action)
            step += 1
            state = env.robot_state
            rolls.append(state.base_rpy_rad[0])
            pitches.append(state.base_rpy_rad[1])
            energy_j += float(np.sum(np.abs(state.joint_torque_nm * state.joint_vel_rad_per_s))) * dt
            max_abs_y = max(max_abs_y, abs(info["lateral_m"]))
            if recorder is not None:
                recorder.on_step(env, obs, action, reward, info)
            if terminated or truncated:
                break
        reason = info["end_reason"]
        progress = info["progress_m"]
        sim_time = step * dt
        if reason == "success":
            time_to_goal = sim_time
        weight_n = cfg.robot.total_mass_kg * cfg.physics.gravity_m_per_s2
        row = {
            "terrain": job.task.terrain, "level": job.task.level, "index": job.index, "seed": job.seed,
            "success": reason == "success", "end_reason": reason, "steps": step, "sim_time_s": sim_time,
            "progress_m": progress, "time_to_goal_s": time_to_goal,
            "mean_forward_speed_m_per_s": progress / sim_time if sim_time > 0 else None,
            "max_abs_y_m": max_abs_y,
            "roll_rms_deg": math.degrees(float(np.sqrt(np.mean(np.square(rolls))))),
            "pitch_rms_deg": math.degrees(float(np.sqrt(np.mean(np.square(pitches))))),
            "cost_of_transport": energy_j / (weight_n * progress) if progress > 0.05 else None,
        }
        if recorder is not None:
            row.update(recorder.on_end(row))
            recorder = None
        return row
    finally:
        if recorder is not None:
            recorder.abort()
        env.close()


def _camera_channel(ctrl, env: HexapodEnv, where: str, timeout_s: float):
    """For a controller with a camera (hexbench.controller.SeeingController): step -> maybe call see(image)."""
    camera = getattr(ctrl, "camera", None)
    if camera is None or not callable(getattr(ctrl, "see", None)):
        return None
    from hexbench.camera import CameraSpec, robot_camera_image
    from hexbench.controller import CAMERA_EVERY_STEPS, CAMERA_GROUND_RGB
    from hexbench.dataset.views import paint_terrain

    if not isinstance(camera, CameraSpec):
        raise ControllerError(f"{where}: camera is a {type(camera).__name__}; expected hexbench.camera.CameraSpec")
    every = getattr(ctrl, "camera_every_steps", CAMERA_EVERY_STEPS)
    if not isinstance(every, int) or every < 1:
        raise ControllerError(f"{where}: camera_every_steps must be a positive int, got {every!r}")
    paint_terrain(env.sim, CAMERA_GROUND_RGB)

    def see(step: int) -> None:
        if step % every:
            return
        image = robot_camera_image(env.sim, camera)
        try:
            with _time_limit(timeout_s):
                ctrl.see(image)
        except _ActTimeout:
            raise ControllerError(f"{where}: see() took longer than {timeout_s:g} s at step {step}") from None
        except BaseException as e:  # noqa: BLE001
            raise ControllerError(f"{where}: see() raised {type(e).__name__} at step {step}: {e}") from None

    return see


def _exit_when_orphaned(parent_pid: int, poll_s: float = 1.0) -> None:
    """Worker-side watchdog: exit as soon as the evaluating process is gone (killed by SIGTERM or
    SIGKILL, it cannot shut its pool down; without this its spawn workers would wait forever)."""
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(1)


def _worker_init(parent_pid: int) -> None:
    import threading

    threading.Thread(target=_exit_when_orphaned, args=(parent_pid,), daemon=True, name="orphan-watchdog").start()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass


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
                 commit: str) -> dict:
    units = {t.terrain: t.unit for t in tasks}
    headroom = {(t.terrain, t.level): t.headroom for t in tasks}
    episode_fields = ("terrain", "level", "index", "seed", "success", "end_reason", "steps", "sim_time_s",
                      "progress_m", "time_to_goal_s", "mean_forward_speed_m_per_s", "max_abs_y_m", "roll_rms_deg",
                      "pitch_rms_deg", "cost_of_transport")
    episodes = sorted(({k: r[k] for k in episode_fields} for r in rows),
                      key=lambda r: (r["terrain"], r["level"], r["index"]))
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
                       "workers": workers},
        "levels": levels,
        "terrains": summarize_terrains(levels),
        "episodes": episodes,
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


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


# -------------------------------------------------------------------------------- the run
@dataclass
class RunResult:
    record: dict | None
    out_dir: Path
    error: str | None = None


def _weights_by_terrain(controller_file: str, tasks: list[TaskSpec], first_ctrl) -> dict[str, list[dict]]:
    """Per terrain, path and sha256 of every weights file the controller loads for it.

    A controller lists them in an optional `checkpoint_paths` attribute (the trained baselines
    do); one controller per terrain is built here, since baselines load per-terrain weights.
    """
    ctrls = {tasks[0].terrain: first_ctrl}
    for task in tasks:
        if task.terrain not in ctrls:
            ctrls[task.terrain] = make_controller(controller_file, task)
    used: dict[str, list[dict]] = {}
    for terrain, ctrl in ctrls.items():
        files = {}
        for path in getattr(ctrl, "checkpoint_paths", []) or []:
            path = Path(path).resolve()
            try:
                shown = str(path.relative_to(Path.cwd()))
            except ValueError:
                shown = str(path)
            files[shown] = {"path": shown, "sha256": file_sha256(path)}
        used[terrain] = [files[k] for k in sorted(files)]
    return used


def evaluate(controller_file: str | Path, tasks: list[TaskSpec], out_dir: str | Path, *, episodes: int | None = None,
             workers: int = 1, record: bool = True, label: str | None = None, progress: bool = True,
             command: str | None = None) -> RunResult:
    """Evaluate one controller file on `tasks`; see the module docstring."""
    controller_file = str(controller_file)
    out = Path(out_dir)
    label = label or Path(controller_file).stem
    command = command or " ".join(["hexbench"] + sys.argv[1:])
    # Load once here: a file that fails to import or build fails before any worker starts.
    ctrl = make_controller(controller_file, tasks[0])
    action_mode = ctrl.action_mode
    weights = _weights_by_terrain(controller_file, tasks, ctrl)
    checkpoints = sorted({w["path"]: w for ws in weights.values() for w in ws}.values(), key=lambda w: w["path"])
    weight_shas = {terrain: sorted(w["sha256"] for w in ws) for terrain, ws in weights.items()}
    sha = file_sha256(controller_file)
    created_out = not out.exists()
    journal = out / ".journal"
    journal.mkdir(parents=True, exist_ok=True)
    record_dir = str(out / "episodes") if record else None
    jobs = [EpisodeJob(controller_file, t, i, s, record_dir)
            for t in tasks for i, s in enumerate(t.seeds(episodes))]
    done: dict[str, dict] = {}
    timing: dict[str, tuple[str, str, float]] = {}  # episode id -> (invocation, its start, elapsed [s] at journaling)
    for job in jobs:
        f = journal / f"{job.episode_id}.json"
        if f.exists():
            entry = json.loads(f.read_text())
            # resumed only if made by the same controller file with the same weights for its terrain
            if entry.get("controller_sha256") == sha and entry.get("protocol") == job.task.protocol \
                    and sorted(w["sha256"] for w in entry.get("weights", [])) == weight_shas[job.task.terrain] \
                    and entry["row"]["seed"] == job.seed and (not record or "mcap_path" in entry["row"]):
                done[job.episode_id] = entry["row"]
                if "invocation" in entry:  # journals written before invocations were kept have no timing
                    timing[job.episode_id] = (entry["invocation"], entry["invocation_started_at"], entry["elapsed_s"])
    todo = [j for j in jobs if j.episode_id not in done]
    written: list[Path] = []
    started_at = datetime.now(timezone.utc).isoformat(timespec="seconds")
    invocation = f"{started_at}/{os.getpid()}"
    commit = git_commit()  # the code that runs, taken before the first episode
    t0 = time.perf_counter()

    def _journal(job: EpisodeJob, row: dict) -> None:
        f = journal / f"{job.episode_id}.json"
        elapsed_s = time.perf_counter() - t0
        _atomic_write_text(f, json.dumps({"controller_sha256": sha, "protocol": job.task.protocol,
                                          "weights": weights[job.task.terrain], "invocation": invocation,
                                          "invocation_started_at": started_at, "elapsed_s": elapsed_s, "row": row}))
        written.append(f)
        done[job.episode_id] = row
        timing[job.episode_id] = (invocation, started_at, elapsed_s)

    error = None
    try:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        with Progress(TextColumn(f"[bold]{label}[/]"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      TimeRemainingColumn(), disable=not progress, transient=False) as bar:
            task_bar = bar.add_task("episodes", total=len(jobs), completed=len(jobs) - len(todo))
            if workers <= 1:
                for job in todo:
                    _journal(job, run_episode(job))
                    bar.advance(task_bar)
            else:
                with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"),
                                         initializer=_worker_init, initargs=(os.getpid(),)) as pool:
                    futures = {pool.submit(run_episode, job): job for job in todo}
                    pending = set(futures)
                    while pending:
                        finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                        for fut in finished:
                            exc = fut.exception()
                            if exc is not None:
                                for p in pending:
                                    p.cancel()
                                raise exc
                            _journal(futures[fut], fut.result())
                            bar.advance(task_bar)
    except ControllerError as e:
        error = str(e)
    except KeyboardInterrupt:
        raise
    if error is not None:
        for f in written:
            f.unlink(missing_ok=True)
        if record_dir is not None:
            for job in todo:
                for suffix in (".mcap", ".rrd"):
                    (Path(record_dir) / f"{job.episode_id}{suffix}").unlink(missing_ok=True)
        if created_out:
            shutil.rmtree(out, ignore_errors=True)
        return RunResult(None, out, error)

    rows = [done[j.episode_id] for j in jobs]
    run_started_at, wall_time_s = run_time([*timing.values(), (invocation, started_at, time.perf_counter() - t0)])
    rec = build_record(label=label, controller_file=controller_file, action_mode=action_mode, tasks=tasks, rows=rows,
                       started_at=run_started_at, wall_time_s=wall_time_s, workers=workers,
                       command=command, checkpoints=checkpoints, commit=commit)
    import pandas as pd

    ordered = sorted(jobs, key=lambda j: (j.task.terrain, j.task.level, j.index))
    table = pd.DataFrame([{"episode_id": j.episode_id, **done[j.episode_id]} for j in ordered])
    tmp = out / ".episodes.parquet.tmp"
    table.to_parquet(tmp, index=False)
    os.replace(tmp, out / "episodes.parquet")
    _atomic_write_text(out / "result.json", json.dumps(rec, indent=1, sort_keys=False) + "\n")
    return RunResult(rec, out)

