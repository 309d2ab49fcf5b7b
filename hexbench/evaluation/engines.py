"""Where a run's episodes are played: the local process pool (the default) or a Ray cluster.

`hexbench run FILE --engine ray [--address ADDR]` hands every episode to Ray as one task that calls
the same `hexbench.evaluation.episode.run_episode(job)` a pool worker calls, so it is sandboxed exactly as in
a local run: the controller runs in its own bubblewrap process inside the Ray worker, and a Ray
worker keeps that process between its tasks (`sandbox.controller_for` caches per process), as a
pool worker does.

What moves between nodes: episode jobs in (task, seed, the controller file's *path*, the run
secret the controller seeds come from); the row and the bytes of the episode's files (action log,
MCAP and .rrd when recording) out. The driver, alone, writes them into OUT/episodes (each file's
sha256 checked against its row first) and journals the episode, so OUT needs to exist on the
driver's machine only and resume works as in a local run. Controller files, their weights and
the Python environment must be at the same paths on every node (the task changes into the
driver's working folder, so relative paths resolve as they do there).

A node that dies mid-run loses no episode: Ray runs its tasks again elsewhere (`max_retries`).
Exceptions raised by an episode are never retried (`retry_exceptions=False`): a controller error
(a `HexbenchError`) is a result, and stops the run with its one line as in a local run.
"""

from __future__ import annotations

import atexit
import contextlib
import contextvars
import os
import shutil
import socket
import tempfile
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

from hexbench.artifacts.files import sha256_bytes, write_bytes_atomic
from hexbench.errors import HexbenchError, OutputError, os_reason
from hexbench.evaluation import sandbox
from hexbench.evaluation.episode import run_episode
from hexbench.evaluation.workers import exit_when_orphaned, pin_to_core, worker_init
from hexbench.suite.controller import ControllerError
from hexbench.suite.numerics import use_controller_math

ENGINES: tuple[str, ...] = ("local", "ray")
RAY_INSTALL = "pip install 'hexbench[ray]'"
DEFAULT_MAX_RETRIES = 5  # per episode task, for node or worker deaths only (never for exceptions it raised)
# Environment the driver passes on to every episode task (set there exactly as on the driver).
FORWARDED_ENV: tuple[str, ...] = ("HEXBENCH_TASKS_DIR",)
# (row key of a file name, row key of its sha256, the job attribute naming the folder it lands in)
EPISODE_FILES: tuple[tuple[str, str, str], ...] = (("action_log_path", "action_log_sha256", "log_dir"),
                                                   ("mcap_path", "mcap_sha256", "record_dir"),
                                                   ("rrd_path", "rrd_sha256", "record_dir"))


class EngineError(HexbenchError):
    """The engine cannot be used (Ray missing, cluster unreachable, an episode lost on the cluster)."""


class LocalEngine:
    """This machine: episodes in this process or a pool of spawn worker processes, each pinned to a core."""

    name = "local"

    def default_workers(self) -> int:
        return os.cpu_count() or 1

    def describe(self) -> str:
        return "local process pool"

    def play_all(self, todo: list, finished, advance, workers: int) -> None:
        """Play every job in this process (`workers` <= 1) or over a spawn pool of `workers` processes,
        each pinned to a core; call `finished(job, row)` as each ends. The first HexbenchError stops
        the rest and propagates; any other failure in a worker becomes a one-line ControllerError."""
        if workers <= 1:
            previous = pin_to_core()
            if previous is not None:  # the controller processes started before (the run's first) go along
                sandbox.pin_all(os.sched_getaffinity(0))
            try:
                for job in todo:
                    finished(job, run_episode(job))
                    advance()
            finally:
                if previous is not None:
                    os.sched_setaffinity(0, previous)
            return
        ctx = get_context("spawn")
        next_core = ctx.Value("i", 0)
        hide = any(getattr(job, "isolation", None) == "process" for job in todo)
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=worker_init,
                                 initargs=(os.getpid(), next_core, hide)) as pool:
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
                        advance()
            finally:
                for p in pending:
                    p.cancel()

    def map(self, fn, items: list, workers: int, advance, stop=None, resources: dict | None = None) -> list:
        """[fn(item) for item in items], in order, in this process (`workers` <= 1: stops early
        once stop(result) holds) or over a spawn pool of `workers` processes; `advance()` per result.
        `fn` must be a module-level function of plain data (replays, scoring, training runs).
        `resources` (what one item needs on a cluster) means nothing here: `workers` is the limit."""
        results = []
        if workers <= 1:
            for item in items:
                results.append(fn(item))
                advance()
                if stop is not None and stop(results[-1]):
                    break
            return results
        with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
            for result in pool.map(fn, items):  # one item at a time: items are episodes or whole runs
                results.append(result)
                advance()
        return results

    def close(self) -> None:
        pass


class RayEngine:
    """Episodes as Ray tasks (one CPU each) on the cluster at `address`.

    address None: Ray's own rule (RAY_ADDRESS, else the cluster started last on this machine, else
    a new local instance); "local": a new local instance of `num_cpus` CPUs (benchmarks, tests).
    """

    name = "ray"

    def __init__(self, address: str | None = None, *, max_retries: int = DEFAULT_MAX_RETRIES,
                 num_cpus: int | None = None, temp_dir: str | None = None):
        self.ray = import_ray()
        self.address, self.max_retries, self.num_cpus, self.temp_dir = address, max_retries, num_cpus, temp_dir
        self._owns_connection = False

    def connect(self) -> RayEngine:
        ray = self.ray
        if ray.is_initialized():
            return self
        import logging

        self._check_reachable()
        kwargs: dict = {"logging_level": logging.WARNING, "log_to_driver": False}
        if self.address == "local":
            kwargs.update(num_cpus=self.num_cpus, include_dashboard=False)
            if self.temp_dir:
                kwargs["_temp_dir"] = self.temp_dir
        try:
            ray.init(address=self.address, **kwargs)
        except Exception as e:  # noqa: BLE001 - ConnectionError, ValueError, RuntimeError ... all one line
            where = f"at {self.address}" if self.address else "(RAY_ADDRESS, the last cluster started here, or a local one)"
            raise EngineError(f"cannot connect to the Ray cluster {where}: {type(e).__name__}: "
                              f"{' '.join(str(e).split())[:300]}") from None
        self._owns_connection = True
        return self

    def _check_reachable(self, timeout_s: float = 10.0) -> None:
        """A HOST:PORT address must accept a connection (ray.init would wait minutes, printing warnings)."""
        host, sep, port = (self.address or "").rpartition(":")
        if not sep or not host or "://" in self.address or not port.isdigit():
            return
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
        except OSError as e:
            raise EngineError(f"cannot reach the Ray cluster at {self.address} "
                              f"({e.strerror or type(e).__name__}); is `ray start --head` running there?") from None

    def default_workers(self) -> int:
        """The cluster's CPUs now: how many episodes run at once (one CPU each)."""
        return max(1, int(self.ray.cluster_resources().get("CPU", 1)))

    def describe(self) -> str:
        nodes = [n for n in self.ray.nodes() if n.get("Alive")]
        return f"Ray cluster ({len(nodes)} node{'s' * (len(nodes) != 1)}, {self.default_workers()} CPUs)"

    def close(self) -> None:
        if self._owns_connection and self.ray.is_initialized():
            self.ray.shutdown()
        self._owns_connection = False

    def __enter__(self) -> RayEngine:
        return self.connect()

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the run
    def play_all(self, todo: list, finished, advance, workers: int) -> None:
        """Play every job as a Ray task, at most `workers` at once; call `finished(job, row)` (in
        this process: it journals) as each ends, after writing its files. The first HexbenchError
        an episode raises stops the rest (cancelled) and propagates."""
        ray = self.ray
        self.connect()
        remote = ray.remote(ray_episode).options(num_cpus=1, max_retries=self.max_retries, retry_exceptions=False)
        cwd = os.getcwd()
        env = {k: os.environ.get(k) for k in FORWARDED_ENV}
        queue = list(todo)
        queue.reverse()
        in_flight: dict = {}
        try:
            while queue or in_flight:
                while queue and len(in_flight) < max(1, workers):
                    job = queue.pop()
                    in_flight[remote.remote(job, cwd, env)] = job
                ready, _ = ray.wait(list(in_flight), num_returns=1)
                for ref in ready:
                    job = in_flight.pop(ref)
                    row, files = self._result(ref, job)
                    land_files(job, row, files)
                    finished(job, row)
                    advance()
        finally:
            for ref in in_flight:
                with contextlib.suppress(Exception):
                    ray.cancel(ref)

    def map(self, fn, items: list, workers: int, advance, stop=None, resources: dict | None = None) -> list:
        """[fn(item) for item in items], in order, as Ray tasks (each asking for `resources`, Ray's
        task options such as {"num_cpus": 2, "num_gpus": 0}; default one CPU), at most `workers` at
        once, retried on node loss, never on an exception `fn` raised; `advance()` per result. The
        items travel to the nodes, so they carry what `fn` needs (an action log's bytes, not its path);
        the driver's FORWARDED_ENV travels with them."""
        ray = self.ray
        self.connect()
        options = {"num_cpus": 1, **(resources or {})}
        remote = ray.remote(call_with_env).options(**options, max_retries=self.max_retries, retry_exceptions=False)
        env = {k: os.environ.get(k) for k in FORWARDED_ENV}
        refs: list = []
        results: list = []
        try:
            for index in range(len(items)):
                while len(refs) - len(results) >= max(1, workers):
                    results.append(self._value(refs[len(results)], "a task"))
                    advance()
                refs.append(remote.remote(fn, items[index], env))
            while len(results) < len(refs):
                results.append(self._value(refs[len(results)], "a task"))
                advance()
        finally:
            for ref in refs[len(results):]:
                with contextlib.suppress(Exception):
                    ray.cancel(ref)
        return results

    def _value(self, ref, what: str):
        ex = self.ray.exceptions
        try:
            return self.ray.get(ref)
        except ex.RayTaskError as e:
            cause = getattr(e, "cause", None)
            if isinstance(cause, HexbenchError):
                raise cause.with_traceback(None) from None
            raise EngineError(f"{what} failed in a Ray worker: {type(cause).__name__ if cause is not None else 'error'}: "
                              f"{' '.join(str(cause if cause is not None else e).split())[:300]}") from None
        except ex.RayError as e:
            raise EngineError(f"{what} was lost on the Ray cluster ({type(e).__name__}, after up to "
                              f"{self.max_retries} retries)") from None

    def _result(self, ref, job) -> tuple[dict, dict[str, bytes]]:
        ex = self.ray.exceptions
        try:
            return self.ray.get(ref)
        except ex.RayTaskError as e:  # the episode raised: a result, never retried
            cause = getattr(e, "cause", None)
            if isinstance(cause, HexbenchError):
                raise cause.with_traceback(None) from None
            raise ControllerError(f"{job.controller_file}: its episode {job.episode_id} failed in a Ray worker: "
                                  f"{type(cause).__name__ if cause is not None else 'error'}: "
                                  f"{' '.join(str(cause if cause is not None else e).split())[:300]}") from None
        except ex.RayError as e:  # worker or node lost more often than max_retries, or the cluster is gone
            raise EngineError(f"{job.controller_file}: its episode {job.episode_id} was lost on the Ray cluster "
                              f"({type(e).__name__}, after up to {self.max_retries} retries)") from None


def land_files(job, row: dict, files: dict[str, bytes]) -> None:
    """Write an episode's files, shipped back by its task, where a local run writes them; each must
    match the sha256 its row states."""
    for name_key, sha_key, folder_attr in EPISODE_FILES:
        name = row.get(name_key)
        if not name:
            continue
        folder = getattr(job, folder_attr)
        data = files.get(name)
        if folder is None or data is None or Path(name).name != name or name in (".", ".."):
            raise EngineError(f"{job.controller_file}: episode {job.episode_id}: its task returned no file {name!r}")
        if sha256_bytes(data) != row.get(sha_key):
            raise EngineError(f"{job.controller_file}: episode {job.episode_id}: {name} does not match its row's sha256")
        write_bytes_atomic(Path(folder) / name, data)


# ------------------------------------------------------------------------ inside a Ray worker
_WORKER: dict = {}


def call_with_env(fn, item, env: dict):
    """fn(item) in a Ray worker, with the driver's FORWARDED_ENV set as on the driver."""
    for key, value in env.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
    return fn(item)


def ray_episode(job, cwd: str, env: dict) -> tuple[dict, dict[str, bytes]]:
    """One episode in a Ray worker: `run_episode(job)` with its files written to a folder of this
    worker (not the driver's OUT, which need not exist here), then returned as bytes."""
    scratch_root = _worker_setup()
    for key, value in env.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
    try:
        os.chdir(cwd)
    except OSError:
        raise EngineError(f"{job.controller_file}: the driver's working folder {cwd} does not exist on node "
                          f"{socket.gethostname()} (controller files must be at the same path on every node)") from None
    if not Path(job.controller_file).is_file():
        raise ControllerError(f"{job.controller_file}: no such controller file on node {socket.gethostname()} "
                              f"(controller files and their weights must be at the same path on every node)")
    run = (job.controller_file, job.isolation, job.limits, job.hidden, job.secret_hex)
    if _WORKER.get("run") != run:  # a Ray worker outlives a run (it serves its driver's job): as a pool
        sandbox.close_all()       # worker's do, the previous run's controller processes end with it
        _WORKER["run"] = run
    try:
        scratch = Path(tempfile.mkdtemp(prefix=f"{job.episode_id}-", dir=scratch_root))
    except OSError as e:
        raise OutputError(f"{scratch_root}: cannot make episode {job.episode_id}'s folder on node "
                          f"{socket.gethostname()} ({os_reason(e)})") from None
    local = replace(job, log_dir=str(scratch) if job.log_dir is not None else None,
                    record_dir=str(scratch) if job.record_dir is not None else None,
                    hidden=(*job.hidden, str(scratch_root)))
    try:
        try:
            row = run_episode(local)
        except BaseException:  # an error, or a cancel mid-call: nothing of this file's controller is reused
            sandbox.drop(job.controller_file)
            raise
        files = {row[key]: (scratch / row[key]).read_bytes() for key, _, _ in EPISODE_FILES if row.get(key)}
        return row, files
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _worker_setup() -> str:
    """Once per Ray worker process, what `worker_init` does for a pool worker: one core (the least
    used by this machine's hexbench Ray workers; the controller process inherits it), one thread
    for numpy/torch, controller processes stopped at exit (and by die-with-parent if the worker
    is killed), exit when the raylet that started the worker is gone. Returns the worker's
    scratch folder for episode files."""
    if "scratch" in _WORKER:
        return _WORKER["scratch"]
    use_controller_math()
    try:
        scratch, core = _claim_worker_folder()
    except OSError as e:
        raise OutputError(f"{tempfile.gettempdir()}: cannot make a Ray worker's scratch folder on node "
                          f"{socket.gethostname()} ({os_reason(e)})") from None
    atexit.register(shutil.rmtree, scratch, True)
    atexit.register(sandbox.close_all)
    threading.Thread(target=exit_when_orphaned, args=(os.getppid(),), daemon=True, name="orphan-watchdog").start()
    if core is not None:
        os.sched_setaffinity(0, {core})
    _WORKER["scratch"] = scratch
    return scratch


def _claim_worker_folder() -> tuple[str, int | None]:
    """This worker's scratch folder, TMP/hexbench-ray-UID/PID (owner-only), and the allowed core
    fewest live hexbench Ray workers of this machine hold (None: nothing to choose). Ray gives no
    core numbers (a pool worker takes the next slot), so they are counted here, under a lock; the
    folders of workers that are gone (Ray kills its workers, so their atexit may never run) are
    removed on the way."""
    import fcntl

    root = Path(tempfile.gettempdir()) / f"hexbench-ray-{os.getuid()}"
    root.mkdir(mode=0o700, exist_ok=True)
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_setaffinity") else []
    held = {c: 0 for c in allowed}
    with open(root / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        for folder in root.iterdir():
            if not folder.is_dir() or not folder.name.isdigit():
                continue
            try:
                os.kill(int(folder.name), 0)
            except ProcessLookupError:
                shutil.rmtree(folder, ignore_errors=True)
                continue
            except OSError:
                pass
            try:
                core = int((folder / "core").read_text())
            except (OSError, ValueError):
                continue
            if core in held and folder.name != str(os.getpid()):
                held[core] += 1
        core = min(allowed, key=lambda c: (held[c], c)) if len(allowed) > 1 else None
        mine = root / str(os.getpid())
        mine.mkdir(mode=0o700, exist_ok=True)
        try:
            (mine / "core").write_text("" if core is None else str(core))
        except OSError:
            shutil.rmtree(mine, ignore_errors=True)
            raise
    return str(mine), core


# ----------------------------------------------------------------------- choosing an engine
_CURRENT: contextvars.ContextVar = contextvars.ContextVar("hexbench_engine", default=None)


def import_ray():
    try:
        import ray
    except ImportError:
        raise EngineError(f"--engine ray needs Ray, which is not installed: {RAY_INSTALL}") from None
    return ray


def make_engine(name: str, address: str | None = None, **options):
    """The engine called `name` (not yet connected); one EngineError line for an unknown name,
    an --address without Ray, or Ray missing."""
    if name not in ENGINES:
        raise EngineError(f"unknown engine {name!r}; valid: {', '.join(ENGINES)}")
    if name == "local":
        if address:
            raise EngineError("--address names a Ray cluster; use it with --engine ray")
        return LocalEngine()
    return RayEngine(address, **options)


def current():
    """The engine episodes and replays run on: the one chosen with `using`, else this machine's pool."""
    return _CURRENT.get() or LocalEngine()


@contextlib.contextmanager
def opened(name: str, address: str | None = None):
    """`make_engine(name, address)` connected (Ray) and in use (`using`) for the block, then closed."""
    engine = make_engine(name, address)
    try:
        if engine.name != "local":
            engine.connect()
        with using(engine):
            yield engine
    finally:
        engine.close()


@contextlib.contextmanager
def using(engine):
    """Play the episodes of every `hexbench.evaluation.evaluate.evaluate` call inside with `engine`."""
    token = _CURRENT.set(engine)
    try:
        yield engine
    finally:
        _CURRENT.reset(token)


__all__ = ["ENGINES", "EngineError", "LocalEngine", "RayEngine", "make_engine", "current", "using", "opened",
           "ray_episode", "call_with_env",
           "land_files", "import_ray"]
