"""The controller process: runs a submitted controller file behind the wire, nothing else.

Started by `hexbench.evaluation.sandbox` as `python -I -B -m hexbench.evaluation.controller_host IN_FD OUT_FD` inside the
sandbox. It first forbids itself new processes, network sockets and any reach into other processes
(seccomp, where libseccomp is available: a filter no later code can lift) and, under process
isolation where the kernel has Landlock, every file but those the sandbox would show; then it
imports the controller file and answers the evaluator's messages (hexbench.evaluation.wire): build
a controller per task, reset it, and turn each observation into an action. Everything it sends is plain data: the action's dtype, shape and
bytes, never an object; the evaluator checks it all again.

This module is the only hexbench code that runs in the untrusted process; the controller can
change anything here, which is why the evaluator trusts nothing it says.
"""

from __future__ import annotations

import dataclasses
import errno
import functools
import os
import sys

import numpy as np

from hexbench.evaluation import wire

CLONE_THREAD = 0x00010000
AF_UNIX = 1


# calls that reach another process by its pid: allowed only where that pid is this process's own
SIGNAL_CALLS_BY_TGID = ("kill", "tgkill", "rt_sigqueueinfo", "rt_tgsigqueueinfo")
OTHER_PROCESS_CALLS = ("ptrace", "process_vm_readv", "process_vm_writev", "tkill", "pidfd_open",
                       "pidfd_send_signal", "pidfd_getfd", "process_madvise", "process_mrelease", "kcmp")
# memory that no address-space limit counts (a memfd's or a SysV segment's pages are the kernel's
# until mapped; 256 memfds of 64 MiB each are 16 GiB), and SysV objects, which outlive the process
# outside an IPC namespace and are shared by id with every process of the same user
MEMORY_OUTSIDE_LIMITS_CALLS = ("memfd_create", "memfd_secret", "shmget", "shmat", "shmctl", "msgget", "msgsnd",
                               "msgrcv", "msgctl", "semget", "semop", "semtimedop", "semctl")
# new namespaces and mounts: in a user namespace of its own a process may mount a tmpfs of any size,
# RAM that no limit counts (measured without this filter: 600 MiB written to a tmpfs mounted with
# size=8g, under bubblewrap); and kernel objects that outlive the process (keyrings), or that only
# widen what the kernel exposes to it (io_uring, eBPF, userfaultfd, perf events), as container
# runtimes' default filters refuse them
NAMESPACE_AND_MOUNT_CALLS = ("unshare", "setns", "mount", "umount2", "pivot_root", "chroot", "fsopen", "fsconfig",
                             "fsmount", "fspick", "move_mount", "open_tree", "mount_setattr")
KERNEL_OBJECT_CALLS = ("add_key", "request_key", "keyctl", "io_uring_setup", "io_uring_enter", "io_uring_register",
                       "bpf", "userfaultfd", "perf_event_open")
# the evaluator pins each worker, and the controller process it starts, to a core of its own: a
# controller that moved its threads elsewhere would take another worker's core
PLACEMENT_CALLS = ("sched_setaffinity",)


def forbid_processes_and_network() -> str:
    """Install a seccomp filter: no fork/vfork/clone without CLONE_THREAD, clone3 unavailable (glibc
    falls back to clone), sockets only of the AF_UNIX family, no memfds, SysV IPC, new namespaces or
    mounts (memory outside the address-space limit), no keyrings, io_uring, eBPF, userfaultfd or perf
    events, no moving off the evaluator's core, and no reach into other processes:
    signals only to this process, no resource limits or priority but its own, no tracing, pidfds
    or cross-process memory calls. Under bubblewrap the evaluator is outside the controller's PID
    namespace anyway; under `--isolation process` it may run as the same user, who could otherwise
    stop, kill or starve it (SIGSTOP, SIGKILL, a file-size limit of 0 set with prlimit).
    Returns what was installed."""
    try:
        import pyseccomp as seccomp
    except Exception:  # noqa: BLE001 - libseccomp or its binding missing: the sandbox records "seccomp: off"
        return "off"
    try:
        deny = seccomp.ERRNO(errno.EPERM)
        own_pid = os.getpid()
        flt = seccomp.SyscallFilter(seccomp.ALLOW)
        for call in ("fork", "vfork"):
            flt.add_rule(deny, call)
        flt.add_rule(seccomp.ERRNO(errno.ENOSYS), "clone3")
        flt.add_rule(deny, "clone", seccomp.Arg(0, seccomp.MASKED_EQ, CLONE_THREAD, 0))
        flt.add_rule(deny, "socket", seccomp.Arg(0, seccomp.NE, AF_UNIX))
        for call in SIGNAL_CALLS_BY_TGID:  # raise(), os.kill(os.getpid()) and pthread_kill still work
            flt.add_rule(deny, call, seccomp.Arg(0, seccomp.NE, own_pid))
        flt.add_rule(deny, "prlimit64", seccomp.Arg(0, seccomp.NE, 0))  # getrlimit/setrlimit pass 0: itself
        flt.add_rule(deny, "setpriority", seccomp.Arg(0, seccomp.NE, 0))  # PRIO_PROCESS only ...
        flt.add_rule(deny, "setpriority", seccomp.Arg(1, seccomp.NE, 0))  # ... of itself
        for call in OTHER_PROCESS_CALLS + PLACEMENT_CALLS:
            flt.add_rule(deny, call)
        for call in MEMORY_OUTSIDE_LIMITS_CALLS + NAMESPACE_AND_MOUNT_CALLS + KERNEL_OBJECT_CALLS:
            try:
                flt.add_rule(deny, call)
            except OSError:  # unknown to an older libseccomp (memfd_secret, mount_setattr): left allowed, the rest kept
                pass
        flt.load()
    except Exception:  # noqa: BLE001
        return "off"
    return "on"


def restrict_files(rules: dict) -> None:
    """Landlock (`--isolation process`, where the kernel has it): from here on this process and its
    threads open only what `rules` name (hexbench.evaluation.isolation.landlock_rules), signal no
    process and reach no abstract socket outside its own Landlock domain, and no process can be
    traced or its /proc memory read from here. Raises if the kernel refuses."""
    from py_landlock import AccessFs, Landlock

    read_file, write_file = AccessFs.READ_FILE, AccessFs.WRITE_FILE | AccessFs.TRUNCATE
    ruleset = Landlock(strict=False).allow_read(*rules["read_folders"]).allow_read_write(*rules["write_folders"])
    ruleset.add_path_rule(*rules["list_folders"], access=AccessFs.READ_DIR)
    ruleset.add_path_rule(*rules["read_files"], access=read_file)
    ruleset.add_path_rule(*rules["write_files"], access=read_file | write_file)
    ruleset.apply()


def declared(ctrl) -> dict:
    """What the evaluator needs to know of a built controller, as plain data."""
    camera = getattr(ctrl, "camera", None)
    info = {"action_mode": getattr(ctrl, "action_mode", None), "has_reset": callable(getattr(ctrl, "reset", None)),
            "has_act": callable(getattr(ctrl, "act", None)), "has_see": callable(getattr(ctrl, "see", None)),
            "camera": None, "camera_type": None,
            "camera_every_steps": getattr(ctrl, "camera_every_steps", None),
            "checkpoint_paths": [str(p) for p in (getattr(ctrl, "checkpoint_paths", None) or [])]}
    if camera is not None:
        info["camera_type"] = f"{type(camera).__module__}.{type(camera).__qualname__}"
        if dataclasses.is_dataclass(camera):
            info["camera"] = dataclasses.asdict(camera)
    if not isinstance(info["action_mode"], str):
        info["action_mode"] = repr(info["action_mode"])[:80]
    if not isinstance(info["camera_every_steps"], int):
        info["camera_every_steps"] = None if info["camera_every_steps"] is None else repr(info["camera_every_steps"])[:80]
    return info


def action_message(action) -> bytes:
    """The ACTION payload for what act() returned: a float array's dtype, shape and bytes, or a
    description of anything else (never the object itself)."""
    if not isinstance(action, np.ndarray):
        return wire.array_payload({"type": type(action).__name__}, b"")
    plain = np.ndarray.view(action, np.ndarray)
    if plain.dtype.kind != "f" or plain.dtype.itemsize not in (4, 8):
        return wire.array_payload({"type": "ndarray", "dtype": str(plain.dtype), "shape": list(plain.shape)}, b"")
    if plain.size > 4096:  # far beyond any action: its shape says enough
        return wire.array_payload({"type": "ndarray", "dtype": f"<f{plain.dtype.itemsize}",
                                   "shape": list(plain.shape)[:8], "truncated": True}, b"")
    return _array_header_line(plain.dtype.itemsize, plain.shape) + _little_endian_bytes(plain)


@functools.lru_cache(maxsize=64)
def _array_header_line(itemsize: int, shape: tuple) -> bytes:
    """The header line of a float array's ACTION payload. A controller returns arrays of one dtype
    and shape step after step, so each line is made once."""
    return wire.array_payload({"type": "ndarray", "dtype": f"<f{itemsize}", "shape": list(shape)}, b"")


def _little_endian_bytes(array: np.ndarray) -> bytes:
    if array.dtype.str[0] != "<":
        array = array.astype(array.dtype.newbyteorder("<"))
    return array.tobytes()  # C order, a copy


class Host:
    def __init__(self, in_fd: int, out_fd: int):
        self.in_fd, self.out_fd = in_fd, out_fd
        self.module = None
        self.controllers: dict[str, object] = {}
        self.current = None

    def send(self, kind: bytes, payload: bytes = b"") -> None:
        wire.write_all(self.out_fd, wire.frame(kind, payload))

    def make(self, request: dict) -> None:
        from hexbench.suite.controller import load_controller_module
        from hexbench.suite.tasks import TaskSpec

        if self.module is None:
            self.module = load_controller_module(request["file"])  # ControllerError: one line, sent as ERROR
        task = TaskSpec(**request["task"])
        name = task.name  # taken before the controller sees (and could change) the task
        ctrl = self.module.make_controller(task)
        self.controllers[name] = ctrl
        self.send(wire.OK, wire.json_payload(declared(ctrl)))

    def handle(self, kind: bytes, payload: bytes) -> None:
        if kind == wire.ACT:
            obs = np.frombuffer(payload, dtype="<f4").astype(np.float32)
            self.send(wire.ACTION, action_message(self.current.act(obs)))
        elif kind == wire.RESET:
            request = wire_json(payload)
            self.current = self.controllers[request["task"]]
            self.current.reset(int(request["seed"]))
            self.send(wire.OK)
        elif kind == wire.SEE:
            header, raw = wire.split_array_payload(payload)
            image = np.frombuffer(raw, dtype=np.uint8).reshape(header["shape"]).copy()
            self.current.see(image)
            self.send(wire.OK)
        elif kind == wire.MAKE:
            self.make(wire_json(payload))
        else:
            raise ValueError(f"unknown message kind {kind!r}")

    def serve(self) -> None:
        inbox = wire.Inbox(self.in_fd)
        while True:
            try:
                kind, payload = inbox.recv()
            except EOFError:
                return
            if kind == wire.QUIT:
                return
            try:
                self.handle(kind, payload)
            except BaseException as e:  # noqa: BLE001 - the controller's failures are reported, never raised
                self.send(wire.ERROR, wire.json_payload({"type": type(e).__name__[:100],
                                                         "message": " ".join(str(e).split())[:500]}))


def wire_json(payload: bytes) -> dict:
    import json

    return json.loads(payload)


def main(argv: list[str]) -> None:
    in_fd, out_fd, seccomp = int(argv[1]), int(argv[2]), argv[3] if len(argv) > 3 else "on"
    landlock = argv[4] if len(argv) > 4 else "off"
    threads = len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else 1
    if threads != 1:  # seccomp and Landlock bind the thread that installs them (and its later threads)
        wire.write_all(out_fd, wire.frame(wire.ERROR, wire.json_payload(
            {"type": "SandboxError", "message": f"the controller process runs {threads} threads before its "
                                                "sandbox is set up; it must run one"})))
        return
    if landlock != "off":
        try:  # binds libc while it may still be looked up (ctypes runs ldconfig: a new process)
            from py_landlock import get_abi_version

            get_abi_version()
        except Exception:  # noqa: BLE001 - reported by restrict_files below
            pass
    if seccomp == "on" and forbid_processes_and_network() != "on":
        wire.write_all(out_fd, wire.frame(wire.ERROR, wire.json_payload(
            {"type": "SandboxError", "message": "the sandbox could not install its seccomp filter (is libseccomp2 installed?)"})))
        return
    if landlock != "off":
        import json

        try:
            with open(landlock) as rules:  # the file hexbench.evaluation.sandbox wrote for this process
                restrict_files(json.load(rules))
        except Exception as e:  # noqa: BLE001 - the evaluator was told Landlock works here: refuse to go on
            wire.write_all(out_fd, wire.frame(wire.ERROR, wire.json_payload(
                {"type": "SandboxError", "message": f"the sandbox could not apply its Landlock rules ({type(e).__name__}: {e})"[:500]})))
            return
    Host(in_fd, out_fd).serve()
    end_now()


def end_now() -> None:
    """End the process without the interpreter's teardown (a torch controller's takes some 0.6 s of
    every run's end) and without the controller's atexit handlers: nothing it holds is needed once
    the evaluator has sent QUIT or closed the pipe. Its output is flushed first (the evaluator keeps
    a stderr tail to report failures with)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a controller may have replaced or closed them
            pass
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv)
