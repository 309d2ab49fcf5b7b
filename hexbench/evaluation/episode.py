"""One episode of a controller file: `run_episode(EpisodeJob)`, and its replay from an action log.

`run_episode` gets the worker's sandboxed controller for the task (hexbench.evaluation.sandbox), plays
the episode through the one episode loop (hexbench.suite.rollout), writes its action log (always:
OUT/episodes/<id>.actions, the proof the record's row can be replayed from) and, when recording,
its MCAP and .rrd, and returns the outcome row. `replay_row` plays the same episode from the action
log alone (no controller); the physics is deterministic, so the rows must be equal.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hexbench.artifacts import action_log
from hexbench.artifacts.files import make_folder, sha256_file
from hexbench.artifacts.provenance import HEXBENCH_VERSION
from hexbench.artifacts.records import ROW_FIELDS
from hexbench.errors import HexbenchError
from hexbench.evaluation import sandbox
from hexbench.suite.controller import MAX_CONTROLLER_FILE_BYTES, ControllerError
from hexbench.suite.rollout import LoggedActions, play
from hexbench.suite.seeds import controller_seed
from hexbench.suite.tasks import TaskSpec, format_level

ACT_TIMEOUT_S = sandbox.DEFAULT_LIMITS.call_timeout_s  # protocol v1: one act() call may take at most this long [s]


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
    controller_sha256: str = ""  # the controller file's sha256 when the run started ("": not checked)

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
        "controller_sha256": job.controller_sha256 or sha256_file(job.controller_file),
        "hexbench_version": HEXBENCH_VERSION,
    }
    return make_episode_recorder(Path(job.record_dir), job.episode_id, meta)


def run_episode(job: EpisodeJob) -> dict:
    """Play one episode; return its outcome row. Raises ControllerError for a bad controller, or for
    a controller file that is no longer the one the run started with."""
    if job.controller_sha256:
        problem = controller_changed(job.controller_file, job.controller_sha256)
        if problem:
            raise ControllerError(problem)
    actor = sandbox.controller_for(job.controller_file, job.task, job.isolation, job.limits, job.hidden,
                                   job.controller_sha256 or None)
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


def controller_changed(controller_file: str, started_sha256: str) -> str | None:
    """Why `controller_file` is not the file a run started with (its sha256 then), or None. A run's
    record names one controller: a file edited mid-run (or, on a cluster, another version on a
    node) would have played some episodes with other code, and a new controller process would
    have been started for it."""
    change = file_change(controller_file, started_sha256, MAX_CONTROLLER_FILE_BYTES, "controller file")
    return None if change is None else f"{controller_file}: {change}"


def file_change(path: str | Path, started_sha256: str, max_bytes: int, what: str) -> str | None:
    """How a file a run's record names (its controller, a weights file) differs from the one hashed
    when the run started, ending in what to do; None if it is the same."""
    try:
        now = sha256_file(path, max_bytes, what)
    except (OSError, HexbenchError) as e:
        return f"can no longer be read during the run ({' '.join(str(e).split())[:200]}): run it again"
    if now == started_sha256:
        return None
    return (f"changed during the run (sha256 {started_sha256[:12]} at its start, {now[:12]} now); "
            f"its episodes would come from two versions of it: run it again")


def row_action_log(task: TaskSpec, row: dict, log_dir: Path) -> action_log.ActionLog:
    """The action log an episode row names, read from `log_dir`: ActionLogError if the row names none,
    or it is missing, corrupt, not the sha256 the row states, or another episode's."""
    where = str(log_dir / str(row.get("action_log_path", "?")))
    if not row.get("action_log_path") or not row.get("action_log_sha256"):
        raise action_log.ActionLogError(f"{task.name} episode {row.get('index')}: the row names no action log")
    log = action_log.read(log_dir / str(row["action_log_path"]), row["action_log_sha256"])
    if (log.terrain, float(log.level), log.index, log.seed) != (task.terrain, float(task.level), row["index"], row["seed"]):
        raise action_log.ActionLogError(f"{where}: the action log belongs to another episode "
                                        f"({log.terrain} {log.level:g} #{log.index}, seed {log.seed})")
    return log


def replay_row(task: TaskSpec, row: dict, log_dir: Path, max_steps: int | None = None) -> dict:
    """Re-simulate an episode row from its action log alone; return the replayed row.

    Raises ActionLogError (see `row_action_log`) or ReplayMismatch.
    """
    log = row_action_log(task, row, log_dir)
    where = str(log_dir / str(row["action_log_path"]))
    return play(task, int(row["seed"]), LoggedActions(log, where), index=int(row["index"]), max_steps=max_steps,
                where=where).row


def first_row_difference(stored: dict, replayed: dict) -> str | None:
    """The first outcome field in which a stored row and its replay differ (exact: the physics is deterministic)."""
    for key in ROW_FIELDS:
        if stored.get(key) != replayed.get(key):
            return f"{key}: recorded {stored.get(key)!r}, replayed {replayed.get(key)!r}"
    return None
