"""How a controller process is isolated: the modes, their resource limits, and how each is started.

`bubblewrap` (the default where `bwrap` works), `process` (the fallback) and `none` (in-process,
for debugging; the leaderboard refuses its records) are described in hexbench.evaluation.sandbox,
which starts the processes. This module decides which mode applies, what a record says about it,
what the process may see (`visible_paths`, `bwrap_argv`, `landlock_rules`), its environment, its rlimits
and capabilities, and what keeps a same-user controller away from the evaluator.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import resource
import shutil
import signal
import stat
import subprocess
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from hexbench.errors import HexbenchError
from hexbench.suite.numerics import CONTROLLER_MATH_ENV

ISOLATIONS: tuple[str, ...] = ("bubblewrap", "process", "none")
SANDBOX_UID = 65534  # nobody
@dataclass(frozen=True)
class Limits:
    """What a controller process may use; the deadlines are enforced by the evaluator."""

    address_space_bytes: int = 4 << 30
    cpu_time_s: int = 4 * 3600  # RLIMIT_CPU of the controller process, over its whole life
    open_files: int = 256
    threads: int = 256  # threads of the controller's process tree at once, checked by the evaluator
    file_size_bytes: int = 64 << 20  # largest file it may write (in its scratch folder)
    scratch_bytes: int = 256 << 20  # size of the scratch folder (bubblewrap's tmpfs)
    small_tmpfs_bytes: int = 16 << 20  # size of /tmp and /dev/shm in the sandbox
    make_timeout_s: float = 120.0  # start-up, import and make_controller(task) [s]
    call_timeout_s: float = 1.0  # CPU time of the controller's process tree per reset(), act() or see() (protocol v1) [s]
    call_wall_timeout_s: float = 10.0  # wall time per call, for controllers that wait instead of computing [s]
    # Waiting: the time a controller's calls take while none of its threads runs or is ready to run
    # (sleeping, blocked) and the evaluator is not kept from running either. Each call may wait as
    # long as the controller computed (a VM's stolen time shows up as waiting) plus wait_free_per_call_s;
    # waiting beyond that is summed over the controller process's life and may reach wait_budget_s.
    wait_free_per_call_s: float = 0.001  # [s]
    wait_budget_s: float = 60.0  # [s]


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
def bubblewrap_disables_userns() -> bool:
    """Whether this bubblewrap can forbid new user namespaces inside its sandbox (`--disable-userns`,
    bubblewrap 0.8.0 and later): in one of its own a process may mount a tmpfs of any size."""
    try:
        return tuple(int(part) for part in (bubblewrap_version() or "").split(".")[:2]) >= (0, 8)
    except ValueError:
        return False


@lru_cache(maxsize=1)
def landlock_abi() -> int:
    """The kernel's Landlock ABI version, 0 where Landlock or its binding (py-landlock) is missing.
    Under `--isolation process` Landlock gives the controller the file view of the bubblewrap
    sandbox without namespaces: read-only what it needs, its scratch folder writable, nothing else."""
    try:
        from py_landlock import get_abi_version

        return int(get_abi_version())
    except Exception:  # noqa: BLE001 - not Linux, Landlock off at boot, or the binding missing
        return 0


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
    return os.geteuid() == 0 and all(readable_by_others(p) for p in
                                     [path, Path(sys.executable).resolve(), *visible_paths(path.parent)])


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
            else "root without capabilities (the Python environment is not readable by nobody)"
    record = {"mode": mode, "sandboxed": True,
              "seccomp": ("no new processes, AF_UNIX sockets only, signals and limits to itself only, "
                          "no memfds, SysV IPC, namespaces, mounts or keyrings, stays on its core")
              if seccomp_available() else "off",
              "user": user,
              "address_space_bytes": limits.address_space_bytes, "cpu_time_s": limits.cpu_time_s,
              "threads": limits.threads,
              "make_timeout_s": limits.make_timeout_s, "call_timeout_s": limits.call_timeout_s,
              "call_wall_timeout_s": limits.call_wall_timeout_s, "wait_free_per_call_s": limits.wait_free_per_call_s,
              "wait_budget_s": limits.wait_budget_s}
    if mode == "bubblewrap":
        record.update(bubblewrap=bubblewrap_version(), network="none (own network namespace)",
                      filesystem="read-only: Python environment, hexbench, controller folder; private scratch")
    else:
        landlock = landlock_abi()
        record.update(network="blocked by seccomp" if seccomp_available() else "open",
                      filesystem=f"Landlock ABI {landlock}: read-only Python environment, hexbench, controller folder, "
                                 f"system libraries; private scratch" if landlock else "not hidden (process fallback)",
                      evaluator_memory="out of reach (the evaluator's processes are not dumpable)")
        if landlock:
            record["landlock_abi"] = landlock
    return record


# ----------------------------------------------------------------------------- process start
def readable_by_others(path: Path) -> bool:
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


def visible_paths(controller_dir: Path) -> list[Path]:
    """What the controller process may read: the Python environment, hexbench, the task files and
    the controller's folder (bubblewrap binds exactly these, read-only)."""
    from hexbench.artifacts.provenance import PACKAGE_DIR
    from hexbench.suite.tasks import tasks_dir

    prefixes = {Path(p).resolve() for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)}
    paths = {*prefixes, Path(sys.executable).resolve().parent, PACKAGE_DIR,
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
DEVICE_FILES = ("/dev/null", "/dev/zero", "/dev/urandom", "/dev/random")  # what a sandbox's /dev holds


def landlock_rules(controller_dir: Path, scratch: Path, hidden: tuple[str, ...] = ()) -> dict[str, list[str]]:
    """What a process-isolated controller may open once Landlock restricts it, the view bubblewrap
    gives: folders to read (the Python environment, hexbench, the task files, the controller's
    folder, the system's library folders and /proc), single files to read (the loader's cache,
    passwd, the usual devices), its scratch folder and /dev/null to write. Landlock only adds
    rights, so a `hidden` path inside a readable folder (the run's journal and logs, a seed key) is
    left out by granting that folder's other entries one by one, and the folders on the way to it
    only their listing: what appears there later (a journal made after the controller started)
    stays out of reach too."""
    hidden_paths = [Path(h).resolve() for h in hidden]
    rules: dict[str, list[str]] = {"read_folders": [], "read_files": [], "list_folders": [],
                                   "write_folders": [str(scratch)], "write_files": ["/dev/null"]}
    for folder in [*visible_paths(controller_dir), *(Path(d) for d in (*SYSTEM_DIRS, "/proc") if os.path.isdir(d))]:
        _grant_read(folder.resolve(), hidden_paths, rules)
    rules["read_files"] += [f for f in (*SYSTEM_FILES, *DEVICE_FILES) if os.path.exists(f)]
    return rules


def _grant_read(path: Path, hidden: list[Path], rules: dict[str, list[str]]) -> None:
    """Read rights on `path` (a folder or a file, not a link), except on the hidden paths within it."""
    if any(path == h or h in path.parents for h in hidden):
        return
    inside = [h for h in hidden if path in h.parents]
    if not path.is_dir():
        rules["read_files"].append(str(path))
    elif not inside:
        rules["read_folders"].append(str(path))
    else:
        rules["list_folders"].append(str(path))
        try:
            entries = sorted(path.iterdir())
        except OSError:
            return
        for entry in entries:
            # A link is not followed: the folder is the submitter's, and a link to / would grant all
            # of it. Its target is readable where some other rule grants it, as in bubblewrap, where
            # a link leads only to what the sandbox binds.
            if not entry.is_symlink():
                _grant_read(entry, hidden, rules)


def bwrap_argv(controller_dir: Path, limits: Limits, hidden: tuple[str, ...] = ()) -> list[str]:
    argv = ["bwrap", "--unshare-all", "--unshare-user", "--uid", str(SANDBOX_UID), "--gid", str(SANDBOX_UID),
            "--cap-drop", "ALL", "--die-with-parent", "--new-session", "--hostname", "sandbox"]
    if bubblewrap_disables_userns():  # the seccomp filter refuses unshare and mount too: this holds without it
        argv += ["--disable-userns"]
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
    visible = visible_paths(controller_dir)
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


def clean_env(home: str) -> dict[str, str]:
    env = {"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": home, "TMPDIR": home, "LANG": "C.UTF-8",
           **CONTROLLER_MATH_ENV}
    if os.environ.get("HEXBENCH_TASKS_DIR"):
        env["HEXBENCH_TASKS_DIR"] = os.environ["HEXBENCH_TASKS_DIR"]
    return env


PR_SET_PDEATHSIG, PR_SET_DUMPABLE, PR_CAPBSET_DROP = 1, 4, 24


def _libc():
    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


def preexec_for(limits: Limits, drop_to_nobody: bool, die_with_parent: bool, drop_capabilities: bool = False):
    """What the child runs between fork and exec: its rlimits, death with its parent, and its user:
    `nobody`, or (`drop_capabilities`, a root evaluator whose Python environment nobody cannot
    read) root with an empty capability bounding set, so that the exec leaves it no capability: it
    cannot read other users' files, trace, or read the memory of a process that is not dumpable."""
    libc = _libc()

    def run() -> None:  # runs in the child between fork and exec
        for what, value in ((resource.RLIMIT_AS, limits.address_space_bytes),
                            (resource.RLIMIT_CPU, limits.cpu_time_s),
                            (resource.RLIMIT_NOFILE, limits.open_files),
                            (resource.RLIMIT_FSIZE, limits.file_size_bytes),
                            (resource.RLIMIT_CORE, 0)):
            resource.setrlimit(what, (value, value))
        if die_with_parent:
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        for capability in range(64 if drop_capabilities else 0):
            if libc.prctl(PR_CAPBSET_DROP, capability, 0, 0, 0) != 0:
                if ctypes.get_errno() == errno.EINVAL:  # past the last capability this kernel knows
                    break
                raise OSError(ctypes.get_errno(), f"cannot drop capability {capability}")
        if drop_to_nobody:
            os.setgroups([])
            os.setgid(SANDBOX_UID)
            os.setuid(SANDBOX_UID)

    return run


def hide_from_controllers() -> None:
    """Make this evaluating process not dumpable: a controller process running as the same user
    (`--isolation process` under a non-root evaluator) can then neither read nor write its memory
    (/proc/PID/mem), nor open its files (/proc/PID/fd) or read its environment. Set in every process
    that starts a process-isolated controller (`ControllerProcess`, the run's main process among
    them), and in every pool worker of such a run before any worker's controller starts (a /proc
    file opened earlier would stay usable). Costs core dumps and same-user debuggers."""
    _libc().prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)


def seed_key_problem(mode: str, controller_file: str | Path, key_file: str | Path | None) -> str | None:
    """Why a controller process under `mode` could read the seed key `key_file` (then hidden seeds
    would be no secret to it), or None. In-process (`none`) the controller shares the evaluator's
    memory, key and all. Under bubblewrap the key is covered up. Under process
    isolation Landlock, where the kernel has it, leaves the key out of what the controller may
    open; without Landlock only `nobody`, the controller's user under a root evaluator, can be
    kept from a key (one that others cannot read)."""
    if key_file is None or mode == "bubblewrap":
        return None
    if mode == "none":
        return (f"{controller_file}: --seed-key with --isolation none: the controller would run inside the "
                f"evaluator, which holds the key; hidden seeds need a sandbox (--isolation bubblewrap or process)")
    as_nobody = runs_as_nobody(controller_file)
    if as_nobody and not readable_by_others(Path(key_file)):
        return None
    if landlock_abi():  # the key is one of the paths its rules leave out (`landlock_rules`)
        return None
    if as_nobody:
        return (f"{controller_file}: --seed-key {key_file}: the controller process runs as nobody, who can read that key; "
                f"keep the key where others cannot read it (chmod o-r), or use bubblewrap isolation")
    who = "root" if os.geteuid() == 0 else "you"
    return (f"{controller_file}: --seed-key {key_file}: under --isolation process its controller process runs as {who} and "
            f"could read the key, so the seeds would not be hidden; hidden seeds need bubblewrap isolation "
            f"(Debian: apt-get install bubblewrap)")
