"""The controller sandbox: a submitted controller runs in a process of its own, isolated, and only
exchanges observations (and camera images) for actions with the evaluator.

Isolation modes (what every record states, `isolation_record`):
  bubblewrap  (default where `bwrap` works) the controller process runs under bubblewrap: new user,
              PID, network, IPC and UTS namespaces (no network at all; it sees only its own
              processes), all capabilities dropped, a read-only view of only the Python
              environment, hexbench's package and task files and the controller's own folder, a
              private /tmp and a size-limited scratch working folder, a clean environment, its own
              session. When the evaluator runs as root the sandbox is started as `nobody`.
  process     (fallback where bubblewrap is missing) a plain child process: own session, clean
              environment, scratch working folder, `nobody` when the evaluator is root. The file
              system is not hidden: it can read what `nobody` can read and write world-writable
              folders such as /tmp. Use it only where bubblewrap cannot be installed.
  none        the controller runs inside the evaluator (debugging only): it can reach the simulator
              and forge its score; records say so and the leaderboard refuses them.
In both sandboxed modes: resource limits (address space 4 GiB, CPU time, open files, file size),
a seccomp filter installed before the controller is imported (no new processes, no sockets but
AF_UNIX; hexbench.controller_host), and deadlines enforced from outside: the evaluator waits for
each answer with a timeout and kills the controller's whole process tree when it passes. Killing
bubblewrap ends its PID namespace, so nothing the controller started outlives it; a dying
evaluator takes it along (`--die-with-parent`, PR_SET_PDEATHSIG).

The evaluator trusts nothing the controller process says: messages are size-limited and parsed as
plain data (hexbench.wire); actions are checked again by `hexbench.controller.check_action`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import dataclasses
import json
import math
import os
import resource
import select
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from hexbench import wire
from hexbench.controller import CAMERA_EVERY_STEPS, ControllerError
from hexbench.controller import make_controller as make_in_process
from hexbench.env import ACTION_MODES
from hexbench.errors import HexbenchError
from hexbench.files import sha256_file

ISOLATIONS: tuple[str, ...] = ("bubblewrap", "process", "none")
SANDBOX_UID = 65534  # nobody
MAX_CAMERA_PIXELS = 640 * 480  # largest camera image a controller may ask the evaluator to render
# Camera spec bounds: rendering happens in the evaluator, outside every deadline, and TinyRenderer
# hangs on a degenerate projection (a field of view of 1e-6 deg), so a spec must be a sane camera.
CAMERA_BOUNDS: dict[str, tuple[float, float]] = {
    "fov_deg": (10.0, 170.0), "mount_forward_m": (-1.0, 1.0), "mount_up_m": (-1.0, 1.0),
    "pitch_down_deg": (-90.0, 90.0), "near_m": (0.005, 1.0), "far_m": (0.1, 50.0)}


@dataclass(frozen=True)
class Limits:
    """What a controller process may use; the deadlines are enforced by the evaluator."""

    address_space_bytes: int = 4 << 30
    cpu_time_s: int = 4 * 3600  # RLIMIT_CPU of the controller process, over its whole life
    open_files: int = 256
    file_size_bytes: int = 64 << 20  # largest file it may write (in its scratch folder)
    scratch_bytes: int = 256 << 20  # size of the scratch folder (bubblewrap's tmpfs)
    small_tmpfs_bytes: int = 16 << 20  # size of /tmp and /dev/shm in the sandbox
    make_timeout_s: float = 120.0  # start-up, import and make_controller(task) [s]
    call_timeout_s: float = 1.0  # CPU time of the controller's process tree per reset(), act() or see() (protocol v1) [s]
    call_wall_timeout_s: float = 10.0  # wall time per call, for controllers that wait instead of computing [s]


DEFAULT_LIMITS = Limits()


# ------------------------------------------------------------------------------ isolation choice
@lru_cache(maxsize=1)
def bubblewrap_version() -> str | None:
    """bubblewrap's version if `bwrap` is installed and can make a sandbox here, else None."""
    exe = shutil.which("bwrap")
    if exe is None:
        return None
    try:
        probe = subprocess.run([exe, "--unshare-all", "--die-with-parent", "--ro-bind", "/", "/", "true"],
                               capture_output=True, timeout=20)
        version = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    if probe.returncode != 0:
        return None
    return version.stdout.strip().replace("bubblewrap ", "") or "unknown"


@lru_cache(maxsize=1)
def seccomp_available() -> bool:
    try:
        import pyseccomp  # noqa: F401
    except Exception:  # noqa: BLE001
        return False
    return True


def resolve_isolation(requested: str) -> str:
    """'auto' -> bubblewrap where it works, else process; a named mode must be usable here."""
    if requested == "auto":
        return "bubblewrap" if bubblewrap_version() else "process"
    if requested not in ISOLATIONS:
        raise HexbenchError(f"unknown isolation {requested!r}; valid: auto, {', '.join(ISOLATIONS)}")
    if requested == "bubblewrap" and not bubblewrap_version():
        raise HexbenchError("bubblewrap is not usable here (Debian: apt-get install bubblewrap); "
                            "or choose --isolation process")
    return requested


def runs_as_nobody(controller_file: str | Path) -> bool:
    """Whether a root evaluator starts this file's controller process as `nobody`: only when nobody
    can read the controller, the Python executable and everything the sandbox shows (a Python
    under /root, say, cannot be; then bubblewrap's user namespace maps uid 65534 onto root, with
    every capability dropped and only the read-only binds visible)."""
    path = Path(controller_file).resolve()
    return os.geteuid() == 0 and all(_readable_by_others(p) for p in
                                     [path, Path(sys.executable).resolve(), *_visible_paths(path.parent)])


def isolation_record(mode: str, limits: Limits = DEFAULT_LIMITS, controller_file: str | Path | None = None) -> dict:
    """The isolation a run's controller processes ran under, as stored in its record."""
    if mode == "none":
        return {"mode": "none", "sandboxed": False}
    if os.geteuid() != 0:
        user = "the evaluating user"
    elif controller_file is not None and runs_as_nobody(controller_file):
        user = "nobody"
    else:
        user = "uid 65534 in a user namespace mapped to root, no capabilities" if mode == "bubblewrap" \
            else "root (the Python environment is not readable by nobody)"
    record = {"mode": mode, "sandboxed": True, "seccomp": "no new processes, AF_UNIX sockets only"
              if seccomp_available() else "off",
              "user": user,
              "address_space_bytes": limits.address_space_bytes, "cpu_time_s": limits.cpu_time_s,
              "make_timeout_s": limits.make_timeout_s, "call_timeout_s": limits.call_timeout_s}
    if mode == "bubblewrap":
        record.update(bubblewrap=bubblewrap_version(), network="none (own network namespace)",
                      filesystem="read-only: Python environment, hexbench, controller folder; private scratch")
    else:
        record.update(network="blocked by seccomp" if seccomp_available() else "open",
                      filesystem="not hidden (process fallback)")
    return record


# ----------------------------------------------------------------------------- process start
def _readable_by_others(path: Path) -> bool:
    """Whether `nobody` can read `path` (world r, and world x on every folder above it)."""
    try:
        path = path.resolve()
        for parent in reversed(path.parents):
            if not os.stat(parent).st_mode & stat.S_IXOTH:
                return False
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return bool(mode & stat.S_IROTH) and (not stat.S_ISDIR(mode) or bool(mode & stat.S_IXOTH))


def _visible_paths(controller_dir: Path) -> list[Path]:
    """What the controller process may read: the Python environment, hexbench, the task files and
    the controller's folder (bubblewrap binds exactly these, read-only)."""
    import hexbench
    from hexbench.tasks import tasks_dir

    prefixes = {Path(p).resolve() for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)}
    paths = {*prefixes, Path(sys.executable).resolve().parent, Path(hexbench.__file__).resolve().parent,
             tasks_dir().resolve(), controller_dir}
    # sys.path entries of the Python environment only: never the working directory or a source tree
    # (a repository root holds run folders, seed keys and other people's results)
    for entry in sys.path:
        if entry and Path(entry).exists():
            resolved = Path(entry).resolve()
            if any(resolved == q or q in resolved.parents for q in prefixes) \
                    or resolved.name in ("site-packages", "dist-packages"):
                paths.add(resolved)
    out = []
    for p in sorted({q.resolve() for q in paths if q.exists()}):
        if not any(p != q and q in p.parents for q in out):
            out.append(p)
    return out


SYSTEM_DIRS = ("/usr", "/bin", "/sbin", "/lib", "/lib64", "/lib32")
SYSTEM_FILES = ("/etc/ld.so.cache", "/etc/ld.so.conf", "/etc/localtime", "/etc/passwd", "/etc/group")


def _bwrap_argv(controller_dir: Path, limits: Limits, hidden: tuple[str, ...] = ()) -> list[str]:
    argv = ["bwrap", "--unshare-all", "--unshare-user", "--uid", str(SANDBOX_UID), "--gid", str(SANDBOX_UID),
            "--cap-drop", "ALL", "--die-with-parent", "--new-session", "--hostname", "sandbox"]
    for d in SYSTEM_DIRS:
        if os.path.islink(d):
            argv += ["--symlink", os.readlink(d), d]
        elif os.path.isdir(d):
            argv += ["--ro-bind", d, d]
    for f in SYSTEM_FILES:
        argv += ["--ro-bind-try", f, f]
    # before the binds (a controller may live in /tmp); every writable tmpfs is sized: RAM written
    # there is not counted by the address-space limit
    small = str(limits.small_tmpfs_bytes)
    argv += ["--proc", "/proc", "--dev", "/dev", "--size", small, "--tmpfs", "/dev/shm", "--size", small, "--tmpfs", "/tmp"]
    visible = _visible_paths(controller_dir)
    for p in visible:
        argv += ["--ro-bind", str(p), str(p)]
    for h in hidden:  # the run's journal and logs, a seed key: never visible, even inside a visible folder
        path = Path(h).resolve()
        if path == controller_dir or path in controller_dir.parents:
            continue  # the controller's own folder stays visible (the caller hides what lies inside it)
        if any(path == v or v in path.parents for v in visible) and path.exists():
            argv += ["--size", "4096", "--tmpfs", str(path)] if path.is_dir() else ["--ro-bind", "/dev/null", str(path)]
    argv += ["--size", str(limits.scratch_bytes), "--tmpfs", "/scratch", "--chdir", "/scratch"]
    return argv


def _clean_env(home: str) -> dict[str, str]:
    env = {"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": home, "TMPDIR": home, "LANG": "C.UTF-8",
           "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    if os.environ.get("HEXBENCH_TASKS_DIR"):
        env["HEXBENCH_TASKS_DIR"] = os.environ["HEXBENCH_TASKS_DIR"]
    return env


def _preexec(limits: Limits, drop_to_nobody: bool, die_with_parent: bool):
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)

    def run() -> None:  # runs in the child between fork and exec
        for what, value in ((resource.RLIMIT_AS, limits.address_space_bytes),
                            (resource.RLIMIT_CPU, limits.cpu_time_s),
                            (resource.RLIMIT_NOFILE, limits.open_files),
                            (resource.RLIMIT_FSIZE, limits.file_size_bytes),
                            (resource.RLIMIT_CORE, 0)):
            resource.setrlimit(what, (value, value))
        if die_with_parent:
            libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if drop_to_nobody:
            os.setgroups([])
            os.setgid(SANDBOX_UID)
            os.setuid(SANDBOX_UID)

    return run


_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
CPU_SAMPLE_EVERY_CALLS = 64  # how often the controller's CPU time is sampled (the sample a slow call is measured from)


class _Deadline:
    """When to give up on an answer: CPU time of the controller (from the latest sample: at most
    CPU_SAMPLE_EVERY_CALLS calls old, so it may include a few ms of earlier calls) and wall time."""

    def __init__(self, process: "ControllerProcess", cpu_s: float | None, wall_s: float):
        self.process, self.cpu_s, self.wall_s = process, cpu_s, wall_s
        self.start = time.monotonic()
        self.expired_on_cpu = False

    def wait_s(self) -> float:
        """Seconds to wait before checking again; 0 when expired."""
        elapsed = time.monotonic() - self.start
        if elapsed >= self.wall_s:
            return 0.0
        if self.cpu_s is None or elapsed < self.cpu_s:
            return min(self.wall_s, self.cpu_s or self.wall_s) - elapsed
        used = self.process.cpu_seconds() - self.process._cpu_sample
        if used >= self.cpu_s:
            self.expired_on_cpu = True
            return 0.0
        return min(0.1, self.wall_s - elapsed)


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


class ControllerProcess:
    """One sandboxed controller process for one controller file; builds a controller per task."""

    def __init__(self, controller_file: str, isolation: str, limits: Limits = DEFAULT_LIMITS,
                 hidden: tuple[str, ...] = ()):
        self.file = str(controller_file)
        self.path = Path(controller_file).resolve()
        self.isolation, self.limits, self.hidden = isolation, limits, hidden
        self.proc: subprocess.Popen | None = None
        self.built: dict[str, RemoteController] = {}
        self._calls, self._cpu_sample = 0, 0.0
        self._start()

    def _start(self) -> None:
        if not self.path.is_file():
            raise ControllerError(f"{self.file}: no such controller file")
        self._tmp = tempfile.mkdtemp(prefix="hexbench-sandbox-")
        self._stderr = open(Path(self._tmp) / "stderr", "w+b")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        host = [sys.executable, "-I", "-B", "-m", "hexbench.controller_host", str(to_child_r), str(from_child_w),
                "on" if seccomp_available() else "off"]
        drop = runs_as_nobody(self.path)
        if self.isolation == "bubblewrap":
            argv, cwd, env, die = _bwrap_argv(self.path.parent, self.limits, self.hidden) + ["--"] + host, "/", \
                _clean_env("/scratch"), False
        else:
            scratch = Path(self._tmp) / "scratch"
            scratch.mkdir()
            if drop:
                os.chown(self._tmp, SANDBOX_UID, SANDBOX_UID)
                os.chown(scratch, SANDBOX_UID, SANDBOX_UID)
            argv, cwd, env, die = host, str(scratch), _clean_env(str(scratch)), True
        try:
            self.proc = subprocess.Popen(argv, pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL,
                                         stdout=subprocess.DEVNULL, stderr=self._stderr, cwd=cwd, env=env,
                                         start_new_session=True, preexec_fn=_preexec(self.limits, drop, die))
        except OSError as e:
            raise ControllerError(f"{self.file}: the controller process could not start ({e})") from None
        finally:
            os.close(to_child_r)
            os.close(from_child_w)
        os.set_blocking(self._to_child, False)
        self._poll_in = select.poll()
        self._poll_in.register(self._from_child, select.POLLIN | select.POLLHUP | select.POLLERR)
        self._poll_out = select.poll()
        self._poll_out.register(self._to_child, select.POLLOUT | select.POLLERR)

    # -- wire
    def _fail(self, problem: str, context: str) -> ControllerError:
        self.kill()
        return ControllerError(f"{self.file}: {problem} {context}".rstrip())

    def _died(self, context: str) -> ControllerError:
        try:
            code = self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            code = None
        self.kill()
        # bubblewrap reports its child's death by signal N as exit code 128 + N
        signum = -code if code is not None and code < 0 else \
            code - 128 if code is not None and code > 128 and self.isolation == "bubblewrap" else None
        if code is None:
            what = "the controller process closed its channel"
        elif signum == signal.SIGSEGV:
            what = "the controller process crashed (SIGSEGV)"
        elif signum is not None:
            what = f"the controller process was killed by {_signal_name(signum)}"
            if signum in (signal.SIGKILL, signal.SIGXCPU):
                what += " (a resource limit?)"
        else:
            what = f"the controller process exited with code {code}"
        tail = self._stderr_tail() if context == "during start-up" else ""
        return ControllerError(f"{self.file}: {what} {context}{': ' + tail if tail else ''}")

    def _stderr_tail(self) -> str:
        try:
            self._stderr.seek(0)
            lines = [line.strip() for line in self._stderr.read()[-4000:].decode(errors="replace").splitlines()]
        except (OSError, ValueError):
            return ""
        lines = [line for line in lines if line]
        return lines[-1][:300] if lines else ""

    def cpu_seconds(self) -> float:
        """CPU time [s] used so far by the controller's process tree (bubblewrap and everything below it)."""
        total, pending, seen = 0, [self.proc.pid], set()
        while pending:
            pid = pending.pop()
            if pid in seen:
                continue
            seen.add(pid)
            try:
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                total += int(fields[11]) + int(fields[12])  # utime, stime [clock ticks]
                for task in Path(f"/proc/{pid}/task").iterdir():
                    pending += [int(c) for c in (task / "children").read_text().split()]
            except (OSError, ValueError, IndexError):
                continue
        return total / _CLOCK_TICKS

    def _send(self, data: bytes, deadline: _Deadline, context: str) -> None:
        view = memoryview(data)
        while view:
            wait_s = deadline.wait_s()
            if wait_s <= 0:
                raise TimeoutError
            if not self._poll_out.poll(max(1, math.ceil(wait_s * 1000))):
                continue
            try:
                view = view[os.write(self._to_child, view):]
            except BlockingIOError:
                continue
            except (BrokenPipeError, OSError):
                raise self._died(context) from None

    def _read(self, n: int, deadline: _Deadline, context: str) -> bytes:
        chunks, got = [], 0
        while got < n:
            wait_s = deadline.wait_s()
            if wait_s <= 0:
                raise TimeoutError
            if not self._poll_in.poll(max(1, math.ceil(wait_s * 1000))):
                continue
            chunk = os.read(self._from_child, n - got)
            if not chunk:
                raise self._died(context)
            chunks.append(chunk)
            got += len(chunk)
        return b"".join(chunks)

    def call(self, kind: bytes, payload: bytes, timeout_s: float, what: str, context: str,
             cpu_limited: bool = True) -> tuple[bytes, bytes]:
        """Send one message and wait for the answer; any failure kills the process and is one ControllerError.

        cpu_limited: the answer may cost the controller `timeout_s` of CPU time and take at most
        `call_wall_timeout_s` of wall time (a loaded machine does not fail an honest controller;
        a sleeping one is still stopped); otherwise `timeout_s` is wall time (start-up, make_controller).
        """
        if self.proc is None:
            raise ControllerError(f"{self.file}: the controller process has already been stopped")
        self._calls += 1
        if cpu_limited and self._calls % CPU_SAMPLE_EVERY_CALLS == 1:
            self._cpu_sample = self.cpu_seconds()
        deadline = _Deadline(self, timeout_s if cpu_limited else None,
                             self.limits.call_wall_timeout_s if cpu_limited else timeout_s)
        try:
            self._send(wire.frame(kind, payload), deadline, context)
            length, answer = wire.HEADER.unpack(self._read(wire.HEADER.size, deadline, context))
            if length > wire.MAX_MESSAGE_BYTES:
                raise self._fail(f"the controller sent a {length:,}-byte message (limit {wire.MAX_MESSAGE_BYTES:,})",
                                 context)
            body = self._read(length, deadline, context) if length else b""
        except TimeoutError:
            limit = f"{timeout_s:g} s of CPU time" if deadline.expired_on_cpu else f"{deadline.wall_s:g} s"
            raise self._fail(f"{what} took longer than {limit}", context + " (controller process killed)") from None
        answer = bytes([answer])
        if answer == wire.ERROR:
            try:
                error = json.loads(body)
                kind, message = _one_line(str(error["type"]), 100), _one_line(str(error["message"]))
            except (ValueError, KeyError, TypeError, RecursionError):
                raise self._fail("sent a malformed error message", context) from None
            if what == "make_controller":
                if kind == "ControllerError":  # loading the file failed: that line says it all
                    raise ControllerError(message)
                context = "" if context == "during start-up" else context
            raise ControllerError(f"{self.file}: {what} raised {kind} {context}".rstrip() + (f": {message}" if message else ""))
        if answer not in (wire.OK, wire.ACTION):
            raise self._fail(f"sent an unknown message kind {answer!r}", context)
        return answer, body

    # -- controllers
    def controller_for(self, task) -> RemoteController:
        if task.name not in self.built:
            context = "during start-up" if not self.built else f"for {task.name}"
            _, body = self.call(wire.MAKE, wire.json_payload({"file": str(self.path), "task": dataclasses.asdict(task)}),
                                self.limits.make_timeout_s, "make_controller", context, cpu_limited=False)
            try:
                info = json.loads(body)
            except (ValueError, RecursionError):
                info = None
            if not isinstance(info, dict):
                raise self._fail("sent a malformed reply to make_controller", context)
            try:
                self.built[task.name] = RemoteController(self, task, info)
            except (TypeError, ValueError, AttributeError, KeyError, RecursionError):
                raise self._fail("sent a malformed reply to make_controller (types of its declared attributes)",
                                 context) from None
        return self.built[task.name]

    def kill(self) -> None:
        """Kill the controller's whole process tree (bubblewrap's namespace goes with it) and clean up."""
        if self.proc is not None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
            self.proc = None
        for fd in (self._to_child, self._from_child):
            try:
                os.close(fd)
            except OSError:
                pass
        self._to_child = self._from_child = -1
        self._stderr.close()
        shutil.rmtree(self._tmp, ignore_errors=True)

    def close(self, grace_s: float = 2.0) -> None:
        """Ask the controller process to quit, give it `grace_s` to exit, then kill whatever is left."""
        if self.proc is not None:
            try:
                os.write(self._to_child, wire.frame(wire.QUIT))
                self.proc.wait(timeout=grace_s)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self.kill()


def _one_line(text: str, limit: int = 300) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit] + "..."


def _camera_from(info: dict, where: str):
    """The CameraSpec a controller declared, rebuilt from plain data and bounded."""
    from hexbench.camera import CameraSpec, Lighting

    if info.get("camera_type") is None or not info.get("has_see"):
        return None
    if info["camera_type"] != "hexbench.camera.CameraSpec" or not isinstance(info.get("camera"), dict):
        shown = str(info["camera_type"]).rsplit(".", 1)[-1][:60]
        raise ControllerError(f"{where}: camera is a {shown}; expected hexbench.camera.CameraSpec")
    fields = dict(info["camera"])
    try:
        if fields.get("lighting") is not None:
            fields["lighting"] = Lighting(**{k: tuple(v) if isinstance(v, list) else v
                                             for k, v in fields["lighting"].items()})
        camera = CameraSpec(**fields)
        numbers = [v for k, v in fields.items() if k != "lighting"]
        ok = all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in numbers)
        ok = ok and isinstance(camera.width_px, int) and isinstance(camera.height_px, int) \
            and camera.width_px * camera.height_px <= MAX_CAMERA_PIXELS and min(camera.width_px, camera.height_px) >= 8
        ok = ok and all(low <= getattr(camera, name) <= high for name, (low, high) in CAMERA_BOUNDS.items()) \
            and camera.far_m > camera.near_m
        if ok and camera.lighting is not None:
            light = camera.lighting
            ok = len(light.direction) == 3 and all(isinstance(v, (int, float)) and math.isfinite(v) and abs(v) <= 10
                                                   for v in (*light.direction, light.ambient, light.diffuse, light.specular))
    except (TypeError, ValueError, AttributeError, RecursionError):
        ok = False
    if not ok:
        bounds = ", ".join(f"{k} {lo:g}..{hi:g}" for k, (lo, hi) in CAMERA_BOUNDS.items())
        raise ControllerError(f"{where}: camera spec is invalid (at least 8 x 8 and at most {MAX_CAMERA_PIXELS} pixels; "
                              f"{bounds}; far_m > near_m)")
    return camera


class RemoteController:
    """The evaluator's handle on a controller built in a sandboxed process (`hexbench.rollout` plays it)."""

    def __init__(self, process: ControllerProcess, task, info: dict):
        where = process.file
        self.process, self.task_name = process, task.name
        if not info.get("has_reset") or not info.get("has_act"):
            missing = "reset" if not info.get("has_reset") else "act"
            raise process._fail(f"controller has no {missing}() method", "")
        self.action_mode = info.get("action_mode")
        if self.action_mode not in ACTION_MODES:
            raise process._fail(f"controller action_mode is {self.action_mode!r}; valid modes: {', '.join(ACTION_MODES)}", "")
        self.camera = _camera_from(info, where)
        every = info.get("camera_every_steps")
        every = CAMERA_EVERY_STEPS if every is None else every
        if self.camera is not None and (not isinstance(every, int) or isinstance(every, bool) or every < 1):
            raise process._fail(f"camera_every_steps must be a positive int, got {every!r}", "")
        self.camera_every_steps = every
        declared = info.get("checkpoint_paths") or []
        if not isinstance(declared, list) or not all(isinstance(p, str) for p in declared):
            raise process._fail("checkpoint_paths must be a list of file names", "")
        self.checkpoint_paths = [self._weights_file(p) for p in declared]

    def _weights_file(self, declared: str) -> Path:
        folder = self.process.path.parent
        try:
            path = Path(declared) if Path(declared).is_absolute() else folder / declared
            path = path.resolve()
            ok = folder in path.parents and path.is_file()
        except (ValueError, OSError, TypeError):  # a NUL byte, a name too long, not a string
            ok = False
        if not ok:
            raise self.process._fail(f"checkpoint path {declared!r} is not a file in the controller's folder", "")
        return path

    def reset(self, seed: int) -> None:
        self.process.call(wire.RESET, wire.json_payload({"task": self.task_name, "seed": int(seed)}),
                          self.process.limits.call_timeout_s, "reset()", "")

    def see(self, image: np.ndarray, step: int) -> None:
        payload = wire.array_payload({"shape": list(image.shape)}, np.ascontiguousarray(image, np.uint8).tobytes())
        self.process.call(wire.SEE, payload, self.process.limits.call_timeout_s, "see()", f"at step {step}")

    def act(self, obs: np.ndarray, step: int):
        """The controller's action as a plain float ndarray, or a description of what it returned
        instead (a str), for `check_action` to turn into the one-line error."""
        context = f"at step {step}"
        _, body = self.process.call(wire.ACT, np.ascontiguousarray(obs, "<f4").tobytes(),
                                    self.process.limits.call_timeout_s, "act()", context)
        try:
            header, raw = wire.split_array_payload(body)
            kind = header.get("type")
            if kind != "ndarray":
                return NotAnArray(str(kind)[:80])
            dtype, shape = str(header["dtype"]), [int(n) for n in header["shape"]]
            if dtype not in ("<f4", "<f8"):
                return WrongDtype(dtype[:40], tuple(shape))
            if header.get("truncated"):
                return WrongShape(tuple(shape))
            count = int(np.prod(shape)) if shape else 1
            if count * int(dtype[-1]) != len(raw):
                raise ValueError("array size does not match its shape")
            return np.frombuffer(raw, dtype=dtype).reshape(shape).astype(np.float64 if dtype == "<f8" else np.float32)
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
            raise self.process._fail("sent a malformed action message", context) from None


@dataclass(frozen=True)
class NotAnArray:
    """act() returned something that is not an ndarray (its type name)."""

    type_name: str


@dataclass(frozen=True)
class WrongShape:
    """act() returned a float array too large to send (its shape only)."""

    shape_only: tuple


@dataclass(frozen=True)
class WrongDtype:
    """act() returned an ndarray of a dtype other than float32/float64."""

    dtype: str
    shape: tuple


# ------------------------------------------------------------------------ in-process (debug)
class _CallTimeout(Exception):
    pass


class InProcessController:
    """isolation 'none': the controller object in the evaluator's own process (debugging only)."""

    def __init__(self, controller_file: str, task, limits: Limits = DEFAULT_LIMITS):
        self.file, self.limits = str(controller_file), limits
        self.ctrl = make_in_process(controller_file, task)
        self.action_mode = self.ctrl.action_mode
        self.checkpoint_paths = [Path(p).resolve() for p in getattr(self.ctrl, "checkpoint_paths", []) or []]
        camera = getattr(self.ctrl, "camera", None)
        self.camera = camera if camera is not None and callable(getattr(self.ctrl, "see", None)) else None
        if self.camera is not None:
            from hexbench.camera import CameraSpec

            if not isinstance(self.camera, CameraSpec):
                raise ControllerError(f"{self.file}: camera is a {type(camera).__name__}; expected hexbench.camera.CameraSpec")
        self.camera_every_steps = getattr(self.ctrl, "camera_every_steps", CAMERA_EVERY_STEPS)
        if self.camera is not None and (not isinstance(self.camera_every_steps, int) or self.camera_every_steps < 1):
            raise ControllerError(f"{self.file}: camera_every_steps must be a positive int, got {self.camera_every_steps!r}")

    def _call(self, what: str, context: str, fn, *args):
        def _raise(signum, frame):
            raise _CallTimeout()

        old = signal.signal(signal.SIGALRM, _raise)
        signal.setitimer(signal.ITIMER_REAL, self.limits.call_timeout_s)
        try:
            return fn(*args)
        except _CallTimeout:
            raise ControllerError(f"{self.file}: {what} took longer than {self.limits.call_timeout_s:g} s {context}".rstrip()) from None
        except ControllerError:
            raise
        except BaseException as e:  # noqa: BLE001
            message = _one_line(str(e))
            raise ControllerError(f"{self.file}: {what} raised {type(e).__name__} {context}".rstrip()
                                  + (f": {message}" if message else "")) from None
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)

    def reset(self, seed: int) -> None:
        self._call("reset()", "", self.ctrl.reset, seed)

    def see(self, image: np.ndarray, step: int) -> None:
        self._call("see()", f"at step {step}", self.ctrl.see, image)

    def act(self, obs: np.ndarray, step: int):
        action = self._call("act()", f"at step {step}", self.ctrl.act, obs.copy())
        if not isinstance(action, np.ndarray):
            return NotAnArray(type(action).__name__)
        plain = np.ndarray.view(action, np.ndarray)
        if plain.dtype.kind != "f":
            return WrongDtype(str(plain.dtype), plain.shape)
        return plain.copy()


# ------------------------------------------------------------------ one process per worker
_PROCESSES: dict[tuple, ControllerProcess] = {}
_IN_PROCESS: dict[tuple, InProcessController] = {}


def controller_for(controller_file: str, task, isolation: str, limits: Limits = DEFAULT_LIMITS,
                   hidden: tuple[str, ...] = ()):
    """The controller for `task` in this worker: one sandboxed process per (file content, isolation),
    reused across tasks and episodes, or an in-process controller for isolation 'none'. `hidden`
    paths (the run folder, a seed key) are covered up inside the sandbox."""
    sha = sha256_file(controller_file) if Path(controller_file).is_file() else ""
    if isolation == "none":
        key = (str(controller_file), sha, task)
        if key not in _IN_PROCESS:
            _IN_PROCESS[key] = InProcessController(controller_file, task, limits)
        return _IN_PROCESS[key]
    key = (str(controller_file), sha, isolation, limits, hidden)
    proc = _PROCESSES.get(key)
    if proc is None or proc.proc is None:
        proc = _PROCESSES[key] = ControllerProcess(controller_file, isolation, limits, hidden)
    try:
        return proc.controller_for(task)
    except ControllerError:
        proc.kill()
        _PROCESSES.pop(key, None)
        raise


def close_all() -> None:
    """Stop every controller process of this worker (end of a run, or the worker's exit)."""
    for proc in list(_PROCESSES.values()):
        proc.close()
    _PROCESSES.clear()
    _IN_PROCESS.clear()


def drop(controller_file: str) -> None:
    """Forget (and stop) this file's controllers: after a failure, nothing of it is reused."""
    for key in [k for k in _PROCESSES if k[0] == str(controller_file)]:
        _PROCESSES.pop(key).close()
    for key in [k for k in _IN_PROCESS if k[0] == str(controller_file)]:
        _IN_PROCESS.pop(key)


__all__ = ["ISOLATIONS", "Limits", "DEFAULT_LIMITS", "ControllerProcess", "RemoteController", "InProcessController",
           "NotAnArray", "WrongDtype", "controller_for", "close_all", "drop", "resolve_isolation", "isolation_record",
           "bubblewrap_version", "load_controller_module"]
