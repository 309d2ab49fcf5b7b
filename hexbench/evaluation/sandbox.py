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
              environment, scratch working folder, `nobody` when the evaluator is root (else root
              without capabilities, or the evaluating user). Where the kernel has Landlock, the
              controller may open only what bubblewrap would show it, and write only its scratch
              folder (`landlock_rules`), which the evaluator keeps within Limits.scratch_bytes
              (`check_scratch`); elsewhere the file system is not hidden: it can read and
              write what its user can. The evaluator's processes are made not dumpable (their
              memory, files and environment are out of a same-user controller's reach), and
              seccomp keeps signals, resource limits and tracing to the controller's own process.
              Use it only where bubblewrap cannot be installed; a seed key the controller could
              read is refused (`seed_key_problem`).
  none        the controller runs inside the evaluator (debugging only): it can reach the simulator
              and forge its score; records say so and the leaderboard refuses them.
In both sandboxed modes: resource limits (address space 4 GiB, CPU time, open files, file size;
threads counted by the evaluator, `check_limits`),
a seccomp filter installed before the controller is imported (no new processes, no sockets but
AF_UNIX; hexbench.evaluation.controller_host), and deadlines enforced from outside: the evaluator waits for
each answer with a timeout and kills the controller's whole process tree when it passes. Killing
bubblewrap ends its PID namespace, so nothing the controller started outlives it; a dying
evaluator takes it along (`--die-with-parent`, PR_SET_PDEATHSIG).

The evaluator trusts nothing the controller process says: messages are size-limited and parsed as
plain data (hexbench.evaluation.wire); actions are checked again by `hexbench.suite.controller.check_action`.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import select
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hexbench.artifacts.files import sha256_file
from hexbench.errors import OutputError, os_reason
from hexbench.evaluation import wire
from hexbench.evaluation.in_process import InProcessController
from hexbench.evaluation.isolation import (
    DEFAULT_LIMITS,
    ISOLATIONS,
    SANDBOX_UID,
    Limits,
    bubblewrap_version,
    bwrap_argv,
    clean_env,
    hide_from_controllers,
    isolation_record,
    landlock_abi,
    landlock_rules,
    preexec_for,
    resolve_isolation,
    runs_as_nobody,
    seccomp_available,
)
from hexbench.evaluation.remote import NotAnArray, RemoteController, WrongDtype, one_line
from hexbench.suite.controller import ControllerError

_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
# The controller's CPU time is sampled, and its waiting counted (Limits.wait_budget_s), once the calls
# since the last count have taken COUNT_AFTER_S of wall time or numbered COUNT_AFTER_CALLS: reading the
# counters costs about 0.25 ms on a loaded 2-core VM (a few us a call amortized), and the sample a slow
# call's CPU time is measured from stays at most some 50 ms of calls old.
COUNT_AFTER_S = 0.05
COUNT_AFTER_CALLS = 64
SCHEDULER_COUNTERS = Path("/proc/thread-self/schedstat").is_file()  # else waiting is not counted
# What no kernel limit bounds here is checked by the evaluator, with each CPU-time sample and every
# LIMITS_CHECK_EVERY_S during a call that takes longer: the controller's threads (Limits.threads; no
# rlimit applies to a user namespace's root, and 3,000 threads took 0.33 s to start, against a
# pid_max of 32,768 on the 2-core VMs), and under process isolation the scratch folder, which is on
# the evaluator's disk, not a sized tmpfs (Limits.scratch_bytes, bubblewrap's tmpfs size). A check
# stats every entry of the folder, so it may hold at most SCRATCH_ENTRIES_MAX files and folders (a
# check then takes a few ms).
LIMITS_CHECK_EVERY_S = 0.25
SCRATCH_ENTRIES_MAX = 10_000


SANDBOX_FOLDER_PREFIX = "hexbench-sandbox-"  # + the evaluating process's pid + "-": its controller processes' folders


def remove_orphaned_sandbox_folders() -> int:
    """Remove the sandbox folders (stderr, scratch, Landlock rules) that evaluating processes which
    are gone left in the temporary folder: a process killed with SIGKILL, or a pool worker ended by
    its orphan watchdog, cannot remove its own. A folder goes only if its name carries the pid of
    no live process and it is a real folder (not a link) owned by this user or, for a root
    evaluator, by nobody. Returns how many went."""
    removed = 0
    root = Path(tempfile.gettempdir())
    try:
        entries = [e for e in os.scandir(root) if e.name.startswith(SANDBOX_FOLDER_PREFIX)]
    except OSError:
        return 0
    owners = {os.geteuid(), SANDBOX_UID} if os.geteuid() == 0 else {os.geteuid()}
    for entry in entries:
        pid, sep, _ = entry.name[len(SANDBOX_FOLDER_PREFIX):].partition("-")
        if not sep or not pid.isdigit() or _process_alive(int(pid)):
            continue
        try:
            status = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if stat.S_ISDIR(status.st_mode) and status.st_uid in owners:
            shutil.rmtree(entry.path, ignore_errors=True)
            removed += 1
    return removed


@functools.lru_cache(maxsize=1)
def _remove_orphaned_sandbox_folders_once() -> int:
    """`remove_orphaned_sandbox_folders`, once per evaluating process (at its first controller)."""
    return remove_orphaned_sandbox_folders()


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def _read_proc(path: str) -> bytes:
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        return os.read(fd, 1 << 16)
    finally:
        os.close(fd)


def _thread_queued_s() -> float:
    """Time [s] this thread has spent queued for a CPU (0 where the kernel keeps no such counter)."""
    if not SCHEDULER_COUNTERS:
        return 0.0
    try:
        return int(_read_proc("/proc/thread-self/schedstat").split()[1]) / 1e9
    except (OSError, ValueError, IndexError):
        return 0.0


def folder_usage(root: str, max_entries: int) -> tuple[int, int]:
    """(bytes allocated on disk, entries) of the files and folders below `root`, links not followed;
    counting stops once there are more than `max_entries`. PermissionError if a folder cannot be read."""
    allocated, entries, pending = 0, 0, [root]
    while pending and entries <= max_entries:
        try:
            with os.scandir(pending.pop()) as listing:
                for entry in listing:
                    entries += 1
                    info = entry.stat(follow_symlinks=False)
                    allocated += info.st_blocks * 512
                    if stat.S_ISDIR(info.st_mode):
                        pending.append(entry.path)
        except FileNotFoundError:  # removed while counting
            continue
    return allocated, entries


def deleted_open_files_bytes(pid: int) -> int:
    """Bytes allocated on disk by the files process `pid` holds open after they were deleted (a
    folder's size no longer shows them). PermissionError if its open files cannot be listed."""
    allocated = 0
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            info = os.stat(f"/proc/{pid}/fd/{fd}")  # the open file itself
        except OSError:  # closed meanwhile, or not a file (a pipe's or socket's link may not resolve)
            continue
        if info.st_nlink == 0 and stat.S_ISREG(info.st_mode):
            allocated += info.st_blocks * 512
    return allocated


def controller_host_boot() -> str:
    """The controller process's program: hexbench's controller host, imported from the package this
    evaluator runs (`python -I` ignores PYTHONPATH, and an installed hexbench may be another checkout
    than the one evaluating; only this package's folder is visible in the sandbox)."""
    from hexbench.artifacts.provenance import PACKAGE_DIR

    return (f"import sys; sys.path.insert(0, {str(PACKAGE_DIR.parent)!r}); "
            "from hexbench.evaluation.controller_host import main; main(sys.argv)")


class _Deadline:
    """When to give up on an answer: CPU time of the controller (from the latest sample, taken when
    the last count of calls ended: it may include some 50 ms of earlier calls) and wall time."""

    def __init__(self, process: "ControllerProcess", cpu_s: float | None, wall_s: float, context: str):
        self.process, self.cpu_s, self.wall_s, self.context = process, cpu_s, wall_s, context
        self.start = time.monotonic()
        self.expired_on_cpu = False

    def wait_s(self) -> float:
        """Seconds to wait before checking again; 0 when expired. Raises ControllerError when the
        controller has gone past a limit the evaluator checks (`ControllerProcess.check_limits`)."""
        elapsed = time.monotonic() - self.start
        if elapsed >= self.wall_s:
            return 0.0
        if elapsed >= LIMITS_CHECK_EVERY_S:
            self.process.check_limits(self.context)
        if self.cpu_s is None or elapsed < self.cpu_s:
            return min(min(self.wall_s, self.cpu_s or self.wall_s) - elapsed, LIMITS_CHECK_EVERY_S)
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
        # the current count of CPU-limited calls (`_start_count`): the controller's CPU time and the
        # busy time at its start [s] (None: no count started), the wall time of its calls [s] and
        # their number; and the waiting counted so far [s] (Limits.wait_budget_s)
        self._cpu_sample, self._count_busy_s = 0.0, None
        self._count_wall_s, self._count_calls, self._waited_s = 0.0, 0, 0.0
        self._inbox = bytearray()  # bytes read from the child and not yet taken
        self.scratch: str | None = None  # the scratch folder the evaluator bounds (process isolation)
        self.threads_seen = 0  # the controller's threads at the latest sample (`tree_times`)
        self._start()

    def _start(self) -> None:
        if not self.path.is_file():
            raise ControllerError(f"{self.file}: no such controller file")
        _remove_orphaned_sandbox_folders_once()
        self._tmp, self._stderr = None, None
        drop = runs_as_nobody(self.path)
        try:
            scratch, landlock_rules_file = self._make_folders(drop)
        except OSError as e:
            if self._stderr is not None:
                self._stderr.close()
            if self._tmp is not None:
                shutil.rmtree(self._tmp, ignore_errors=True)
            raise OutputError(f"{tempfile.gettempdir()}: cannot make the folder of {self.file}'s controller process "
                              f"({os_reason(e)})") from None
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        host = [sys.executable, "-I", "-B", "-c", controller_host_boot(), str(to_child_r), str(from_child_w),
                "on" if seccomp_available() else "off", landlock_rules_file or "off"]
        if self.isolation == "bubblewrap":
            argv, cwd, env, die = bwrap_argv(self.path.parent, self.limits, self.hidden) + ["--"] + host, "/", \
                clean_env("/scratch"), False
        else:
            hide_from_controllers()  # the same user may run it: it must not reach this process's memory
            argv, cwd, env, die = host, str(scratch), clean_env(str(scratch)), True
            self.scratch = str(scratch)
        drop_capabilities = self.isolation == "process" and os.geteuid() == 0 and not drop
        try:
            self.proc = subprocess.Popen(argv, pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL,
                                         stdout=subprocess.DEVNULL, stderr=self._stderr, cwd=cwd, env=env,
                                         start_new_session=True,
                                         preexec_fn=preexec_for(self.limits, drop, die, drop_capabilities))
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

    def _make_folders(self, for_nobody: bool) -> tuple[Path | None, str | None]:
        """The controller process's folder in the temporary folder, with its stderr file; under
        process isolation also its scratch folder (owned by nobody where `for_nobody`: the process
        runs as nobody) and, where Landlock works, its rules file (the rules go in a file: one per
        entry of a folder can outgrow an argument). Returns (scratch folder, rules file), each None
        where there is none."""
        self._tmp = tempfile.mkdtemp(prefix=f"{SANDBOX_FOLDER_PREFIX}{os.getpid()}-")
        self._stderr = open(Path(self._tmp) / "stderr", "w+b")
        if self.isolation == "bubblewrap":
            return None, None
        scratch = Path(self._tmp) / "scratch"
        scratch.mkdir()
        if for_nobody:
            os.chown(self._tmp, SANDBOX_UID, SANDBOX_UID)
            os.chown(scratch, SANDBOX_UID, SANDBOX_UID)
        if not landlock_abi():
            return scratch, None
        rules = Path(self._tmp) / "landlock-rules.json"
        rules.write_text(json.dumps(landlock_rules(self.path.parent, scratch, self.hidden)))
        rules.chmod(0o644)
        return scratch, str(rules)

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
            self._stderr.seek(max(0, os.fstat(self._stderr.fileno()).st_size - 4000))  # up to 64 MiB written
            lines = [line.strip() for line in self._stderr.read(4000).decode(errors="replace").splitlines()]
        except (OSError, ValueError):
            return ""
        lines = [line for line in lines if line]
        return lines[-1][:300] if lines else ""

    def _tree(self):
        """Each process of the controller's tree (bubblewrap and everything below it) with its thread
        ids, parents first; processes that end meanwhile are left out. Read with plain system calls:
        about 10 us a file, against 100 us and more through pathlib."""
        pending, seen = [self.proc.pid] if self.proc is not None else [], set()
        while pending:
            pid = pending.pop()
            if pid in seen:
                continue
            seen.add(pid)
            try:
                tids = os.listdir(f"/proc/{pid}/task")
            except OSError:  # the process has ended
                continue
            for tid in tids:
                try:
                    pending += [int(c) for c in _read_proc(f"/proc/{pid}/task/{tid}/children").split()]
                except (OSError, ValueError):  # a thread that ended meanwhile: its process still counts
                    continue
            yield pid, tids

    def tree_times(self, queued: bool = True) -> tuple[float, float]:
        """CPU time [s] used so far by the controller's process tree (exited threads included), and
        the time its live threads have spent queued for a CPU [s] (the scheduler's per-thread
        counters; 0 where the kernel keeps none, or if not `queued`). Also keeps the number of the
        tree's threads in `threads_seen`."""
        ticks, queued_ns, threads = 0, 0, 0
        queued = queued and SCHEDULER_COUNTERS
        for pid, tids in self._tree():
            try:
                fields = _read_proc(f"/proc/{pid}/stat").rsplit(b")", 1)[1].split()
                ticks += int(fields[11]) + int(fields[12])  # utime, stime [clock ticks]
                threads += int(fields[17])  # num_threads
                for tid in tids if queued else ():
                    queued_ns += int(_read_proc(f"/proc/{pid}/task/{tid}/schedstat").split()[1])
            except (OSError, ValueError, IndexError):
                continue
        self.threads_seen = threads
        return ticks / _CLOCK_TICKS, queued_ns / 1e9

    def check_limits(self, context: str, sampled: bool = False) -> None:
        """Kill the controller (one ControllerError) past a limit the evaluator checks: its threads and,
        under process isolation, its scratch folder. `sampled`: the tree's threads were just counted."""
        if not sampled:
            self.tree_times(queued=False)
        self.check_threads(context)
        if self.scratch is not None:
            self.check_scratch(context)

    def check_threads(self, context: str) -> None:
        """Kill the controller (one ControllerError) if the latest sample counted more threads than
        Limits.threads (bubblewrap's own processes included)."""
        if self.threads_seen > self.limits.threads:
            raise self._fail(f"ran {self.threads_seen:,} threads, more than the {self.limits.threads} a controller "
                             "may", context + " (controller process killed)")

    def check_scratch(self, context: str) -> None:
        """Kill the controller (one ControllerError) if its scratch folder, with the deleted files it
        still holds open, takes more than Limits.scratch_bytes, or holds more than SCRATCH_ENTRIES_MAX
        files and folders."""
        try:
            allocated, entries = folder_usage(self.scratch, SCRATCH_ENTRIES_MAX)
            allocated += deleted_open_files_bytes(self.proc.pid)
        except FileNotFoundError:  # it has just ended (its /proc folder is gone): the next call says how
            return
        except OSError:  # a folder made unreadable, or its open files hidden (made not dumpable)
            raise self._fail("hid part of its scratch folder or its open files from the evaluator's count",
                             context + " (controller process killed)") from None
        if allocated > self.limits.scratch_bytes:
            raise self._fail(f"wrote more than {self.limits.scratch_bytes >> 20} MiB to its scratch folder "
                             "(the limit of every sandbox's scratch folder)", context + " (controller process killed)")
        if entries > SCRATCH_ENTRIES_MAX:
            raise self._fail(f"made more than {SCRATCH_ENTRIES_MAX:,} files and folders in its scratch folder",
                             context + " (controller process killed)")

    def pin(self, cores: set[int]) -> None:
        """Pin every thread of the controller's process tree to `cores` (one started before its
        worker pinned itself would float over every core; it cannot change its own placement)."""
        for _, tids in self._tree():
            for tid in tids:
                try:
                    os.sched_setaffinity(int(tid), cores)
                except OSError:  # ended meanwhile
                    pass

    def cpu_seconds(self) -> float:
        """CPU time [s] used so far by the controller's process tree."""
        return self.tree_times(queued=False)[0]

    def _start_count(self) -> None:
        """Start counting calls afresh: the CPU-time sample a slow call's CPU time is measured from,
        and the busy time the waiting of the calls to come is measured against: the time the
        controller ran or was queued for a CPU, plus the time this evaluator thread was queued."""
        cpu_s, queued_s = self.tree_times()
        self._cpu_sample = cpu_s
        self._count_busy_s = cpu_s + queued_s + _thread_queued_s()
        self._count_wall_s, self._count_calls = 0.0, 0

    def _count_waiting(self, what: str, context: str) -> None:
        """Add the waiting of the calls since the count started (their wall time less the busy time,
        less what each call may wait: as long as the controller computed, plus
        wait_free_per_call_s) to the controller's total, start a new count, and fail past wait_budget_s."""
        wall_s, calls, busy_before_s = self._count_wall_s, self._count_calls, self._count_busy_s
        self._start_count()
        if not SCHEDULER_COUNTERS:
            return
        busy_s = self._count_busy_s - busy_before_s
        self._waited_s += max(0.0, wall_s - 2 * busy_s - calls * self.limits.wait_free_per_call_s)
        if self._waited_s > self.limits.wait_budget_s:
            raise self._fail(f"{what} waited without computing (sleeping or blocked) "
                             f"for {self._waited_s:.0f} s in all, "
                             f"beyond the {self.limits.wait_budget_s:g} s a controller may (each call may wait as "
                             f"long as it computes, plus {self.limits.wait_free_per_call_s * 1e3:g} ms)",
                             context + " (controller process killed)")

    def _send(self, data: bytes, deadline: _Deadline, context: str) -> None:
        view = memoryview(data)
        try:  # a message fits the pipe's buffer whenever the child has read the previous one: no poll first
            view = view[os.write(self._to_child, view):]
        except BlockingIOError:
            pass
        except (BrokenPipeError, OSError):
            raise self._died(context) from None
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

    def _receive(self, deadline: _Deadline, context: str) -> tuple[bytes, bytes]:
        """The child's next whole message: (kind, body). Reads take what the pipe holds (a reply
        usually arrives whole in one read); bytes beyond the message wait in the inbox for the next
        call. A message declaring more than MAX_MESSAGE_BYTES is refused before its body is read."""
        inbox, header_size = self._inbox, wire.HEADER.size
        while True:
            if len(inbox) >= header_size:
                length, kind = wire.HEADER.unpack_from(inbox)
                if length > wire.MAX_MESSAGE_BYTES:
                    raise self._fail(f"the controller sent a {length:,}-byte message "
                                     f"(limit {wire.MAX_MESSAGE_BYTES:,})", context)
                end = header_size + length
                if len(inbox) >= end:
                    body = bytes(inbox[header_size:end])
                    del inbox[:end]
                    return wire.KINDS[kind], body
            wait_s = deadline.wait_s()
            if wait_s <= 0:
                raise TimeoutError
            if not self._poll_in.poll(max(1, math.ceil(wait_s * 1000))):
                continue
            chunk = os.read(self._from_child, max(end - len(inbox) if len(inbox) >= header_size else 0,
                                                  wire.READ_CHUNK_BYTES))
            if not chunk:
                raise self._died(context)
            inbox += chunk

    def call(self, kind: bytes, payload: bytes, timeout_s: float, what: str, context: str,
             cpu_limited: bool = True, waiting_counted: bool | None = None) -> tuple[bytes, bytes]:
        """Send one message and wait for the answer; any failure kills the process and is one ControllerError.

        cpu_limited: the answer may cost the controller `timeout_s` of CPU time and take at most
        `call_wall_timeout_s` of wall time (a loaded machine does not fail an honest controller;
        a sleeping one is still stopped); otherwise `timeout_s` is wall time (start-up, make_controller).
        waiting_counted: whether the call's waiting counts against Limits.wait_budget_s (default:
        if cpu_limited; start-up, with its imports from disk, is never counted).
        """
        if self.proc is None:
            raise ControllerError(f"{self.file}: the controller process has already been stopped")
        counted = cpu_limited if waiting_counted is None else waiting_counted
        if not counted:
            self._count_busy_s = None  # the next count starts afresh after this call
        elif self._count_busy_s is None:
            self._start_count()
        deadline = _Deadline(self, timeout_s if cpu_limited else None,
                             self.limits.call_wall_timeout_s if cpu_limited else timeout_s, context)
        try:
            self._send(wire.frame(kind, payload), deadline, context)
            answer, body = self._receive(deadline, context)
        except TimeoutError:
            limit = f"{timeout_s:g} s of CPU time" if deadline.expired_on_cpu else f"{deadline.wall_s:g} s"
            raise self._fail(f"{what} took longer than {limit}", context + " (controller process killed)") from None
        if counted:
            self._count_wall_s += time.monotonic() - deadline.start
            self._count_calls += 1
            if self._count_wall_s > COUNT_AFTER_S or self._count_calls >= COUNT_AFTER_CALLS:
                self._count_waiting(what, context)  # samples the tree's threads too
                self.check_limits(context, sampled=True)
        else:
            self.check_limits(context)
        if answer == wire.ERROR:
            try:
                error = json.loads(body)
                kind, message = one_line(str(error["type"]), 100), one_line(str(error["message"]))
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
            # after start-up, make_controller's waiting is counted: one that sleeps must not cost
            # make_timeout_s for each task of the suite (43 in protocol v1)
            _, body = self.call(wire.MAKE, wire.json_payload({"file": str(self.path), "task": dataclasses.asdict(task)}),
                                self.limits.make_timeout_s, "make_controller", context, cpu_limited=False,
                                waiting_counted=bool(self.built))
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


# ------------------------------------------------------------------ one process per worker
_PROCESSES: dict[tuple, ControllerProcess] = {}
_IN_PROCESS: dict[tuple, InProcessController] = {}


def controller_for(controller_file: str, task, isolation: str, limits: Limits = DEFAULT_LIMITS,
                   hidden: tuple[str, ...] = (), sha256: str | None = None):
    """The controller for `task` in this worker: one sandboxed process per (file content, isolation),
    reused across tasks and episodes, or an in-process controller for isolation 'none'. `hidden`
    paths (the run folder, a seed key) are covered up inside the sandbox. `sha256`: the file's, where
    the caller has just checked it (else it is hashed here)."""
    sha = sha256 or (sha256_file(controller_file) if Path(controller_file).is_file() else "")
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


def pin_all(cores: set[int]) -> None:
    """Pin this worker's controller processes to `cores` (what the worker has just pinned itself to)."""
    for proc in _PROCESSES.values():
        proc.pin(cores)


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


__all__ = ["ControllerError", "seccomp_available", "ISOLATIONS", "Limits", "DEFAULT_LIMITS", "ControllerProcess", "RemoteController", "InProcessController",
           "NotAnArray", "WrongDtype", "controller_for", "pin_all", "close_all", "drop", "resolve_isolation", "isolation_record",
           "bubblewrap_version"]
