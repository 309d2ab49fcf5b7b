"""Red team: hostile controller files (tests/controllers/attack_*.py) run through the real CLI.

Each attack file walks like the open-loop CPG (which fails stairs 8 cm: 0 successes) and adds one
attack, described in its docstring. Each is run as

    python -m hexbench run FILE --terrain stairs --levels 8 --episodes 1 --workers 1 --no-record --out DIR

from the repository root, and the outcome must be honest:
  * exit 0: DIR/result.json holds one stairs-8 episode that failed, and the real sha256 of FILE; or
  * exit 1: stderr is exactly one line, "error: ..." naming FILE, and no result.json was written;
  * never a traceback, and within the case's time bound;
and whatever the exit, the run leaves nothing behind: no process with an attack marker (or the
controller's path, or the run's folder) in its command line, no attack file outside the test's
tmp_path, no change to `git status` of the repository, no connection to the test's servers.
`CASES` says per file which exits are acceptable (a file can appear twice, as "name@variant", with
another output-folder layout). The file-system and network attacks can only be
stopped by a sandbox (bubblewrap); those cases are skipped where `bwrap` is not installed.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
import re
import select
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from hexbench.evaluation.isolation import landlock_abi

REPO = Path(__file__).resolve().parent.parent
CONTROLLERS = REPO / "tests" / "controllers"
CPG = REPO / "baselines" / "cpg.py"
MARKER = "hexbench-attack-marker"  # in the argv of every process an attack leaves behind
# `make test` runs pytest-xdist with --dist loadfile, so the attacks run one at a time in one test
# process: what one attack leaves behind is looked for machine-wide (the marker, the corpus file's
# path), and a second attack running beside it would be counted as its leftover, and killed.
OUTPUT_MARKER = "hexbench-attack-output"  # in every text an attack prints
HAVE_BWRAP = shutil.which("bwrap") is not None
CONTROL_CHARS = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")  # what may not reach the user's terminal

ERROR = "error"  # must exit 1 with one error line
HONEST = "honest"  # must exit 0 with an honest (failed) score
EITHER = "either"  # either of the two


@dataclass(frozen=True)
class Case:
    expect: str
    max_s: float = 60.0  # the whole command's wall time [s]
    needs_bwrap: bool = False  # only a sandbox can stop it
    needs_landlock: bool = False  # under --isolation process, only Landlock can stop it
    then_cpg: bool = False  # baselines/cpg.py follows on the same command line and must still be evaluated
    extra_args: tuple[str, ...] = ()
    error_words: tuple[str, ...] = ()  # the error line names one of these (case-insensitive)
    slow: bool = False  # over a minute: runs with `-m slow`
    out: str = ""  # the output folder: "" tmp_path/out; "runs": runs/<name>-v1 next to a copy of the file (the
    # default layout when the file sits in the working directory); "same": the copy's own folder
    sparse_files: tuple[tuple[str, int], ...] = ()  # (name, size [bytes]) of sparse files made beside a copy of the file
    seed_key: bool = False  # run with --seed-key, a key file beside a copy of the file (mode 644, in an owner-only folder)
    link_outside: bool = False  # beside a copy of the file, a link `outside` to a folder the sandbox does not show


TIMEOUT_WORDS = ("timeout", "timed out", "took longer", "deadline", "time limit")
PROCESS = ("--isolation", "process")
CASES: dict[str, Case] = {
    "attack_teleport": Case(EITHER),
    "attack_slide": Case(EITHER),
    "attack_monkeypatch_judge": Case(EITHER),
    "attack_gc_env": Case(EITHER),
    "attack_stack_frames": Case(EITHER),
    "attack_patch_record": Case(EITHER),
    "attack_sys_modules": Case(EITHER),
    "attack_task_mutation": Case(EITHER),
    "attack_thread_after_act": Case(EITHER),
    "attack_seed_foresight": Case(HONEST),
    "attack_run_secret": Case(HONEST, out="runs"),
    "attack_run_secret@same-folder": Case(HONEST, out="same"),  # `hexbench run ./mine.py --out .`
    "attack_run_secret@process": Case(HONEST, out="runs", needs_landlock=True, extra_args=PROCESS),
    "attack_run_secret@process-same-folder": Case(HONEST, out="same", needs_landlock=True, extra_args=PROCESS),
    "attack_proc_parent": Case(HONEST, needs_bwrap=True),
    # under --isolation process the controller may run as the evaluator's user (or as root): only
    # seccomp and an evaluator that is not dumpable keep it from the evaluator's processes
    "attack_signal_evaluator": Case(HONEST),
    "attack_signal_evaluator@process": Case(HONEST, extra_args=PROCESS),
    "attack_evaluator_memory": Case(HONEST),
    "attack_evaluator_memory@process": Case(HONEST, extra_args=PROCESS),
    "attack_read_seed_key": Case(HONEST, seed_key=True, needs_bwrap=True),
    # refused where the controller process could read the key; where Landlock leaves the key out, or
    # the controller runs as nobody and nobody cannot read it (the test's owner-only folder), it
    # must score honestly
    "attack_read_seed_key@process": Case(EITHER, seed_key=True, extra_args=PROCESS, error_words=("--seed-key",)),
    "attack_link_outside": Case(HONEST, link_outside=True, out="runs", needs_bwrap=True),
    "attack_link_outside@process": Case(HONEST, link_outside=True, out="runs", needs_landlock=True, extra_args=PROCESS),
    "attack_write_outside": Case(EITHER, needs_bwrap=True),
    "attack_write_outside@process": Case(EITHER, needs_landlock=True, extra_args=PROCESS),
    "attack_overwrite_source": Case(EITHER, needs_bwrap=True),
    "attack_overwrite_source@process": Case(EITHER, needs_landlock=True, extra_args=PROCESS),
    "attack_socket": Case(EITHER, needs_bwrap=True),
    "attack_socket@process": Case(EITHER, needs_landlock=True, extra_args=PROCESS),
    "attack_detached_child": Case(EITHER),
    "attack_fork": Case(EITHER),
    "attack_memory_bomb": Case(EITHER),
    "attack_stdout_garbage": Case(EITHER),
    "attack_pickle_reduce": Case(EITHER),
    "attack_wire_nesting": Case(EITHER),
    "attack_checkpoint_path": Case(ERROR),
    "attack_huge_checkpoint": Case(ERROR, max_s=30.0, sparse_files=(("huge_weights.bin", 200 << 30),),
                                   error_words=("bytes",)),
    "attack_camera_spec": Case(EITHER, max_s=20.0),
    "attack_wire_make_info": Case(EITHER),
    "attack_stderr_injection": Case(ERROR),
    "attack_tmpfs_fill": Case(HONEST, needs_bwrap=True),
    "attack_memory_outside_limits": Case(HONEST),
    "attack_memory_outside_limits@process": Case(HONEST, extra_args=PROCESS),
    "attack_namespace_tmpfs": Case(HONEST),
    "attack_namespace_tmpfs@process": Case(HONEST, extra_args=PROCESS),
    "attack_keyring": Case(HONEST),
    "attack_keyring@process": Case(HONEST, extra_args=PROCESS),
    "attack_leave_core": Case(HONEST),
    "attack_leave_core@process": Case(HONEST, extra_args=PROCESS),
    "attack_thread_bomb": Case(ERROR, max_s=30.0, error_words=("threads",)),
    "attack_thread_bomb@process": Case(ERROR, max_s=30.0, extra_args=PROCESS, error_words=("threads",)),
    "attack_ndarray_subclass": Case(EITHER),
    "attack_huge_message": Case(ERROR, error_words=("shape", "size", "bytes", "large", "long", "length")),
    "attack_os_exit": Case(ERROR, then_cpg=True),
    "attack_segfault": Case(ERROR, then_cpg=True),
    "attack_hang_make": Case(ERROR, max_s=30.0, extra_args=("--make-timeout", "5")),
    # a call that waits (sleeps) rather than computes gets up to 10 s of wall time (hexbench.evaluation.sandbox.Limits)
    "attack_swallow_timeout": Case(ERROR, max_s=30.0, error_words=TIMEOUT_WORDS),
    "attack_ignore_sigalrm": Case(ERROR, max_s=20.0, error_words=TIMEOUT_WORDS),
    "attack_c_busy_act": Case(ERROR, max_s=20.0, error_words=TIMEOUT_WORDS),
    "attack_cpu_burn_reset": Case(ERROR, max_s=20.0, error_words=TIMEOUT_WORDS),
    # each call within its limits, but a minute of waiting in all is the most a controller may spend
    "attack_slow_loris": Case(ERROR, max_s=120.0, slow=True, error_words=("waited without computing",)),
}


# ------------------------------------------------------------------------ what an attack leaves
def _site_dirs() -> list[Path]:
    dirs = {Path(p) for p in sys.path if p.endswith("site-packages")}
    dirs |= set((REPO / ".venv" / "lib").glob("python*/site-packages"))
    return sorted(d for d in dirs if d.is_dir())


def _attack_files(tmp_path: Path) -> list[Path]:
    """Files the attacks try to create outside the controller's own process, that exist now."""
    fixed = [Path.home() / "hexbench-attack-write", REPO / "hexbench-attack-write",
             CONTROLLERS / "hexbench-attack-write", REPO / "hexbench" / "hexbench_attack_write.py",
             Path("/work/main/hexbench-attack-write"), Path("/work/main/hexbench/hexbench_attack_write.py")]
    found = sorted({p for p in fixed if p.exists()})
    for d in (Path("/tmp"), Path("/dev/shm")):
        found += sorted(d.glob("hexbench[-_]attack*"))
    for d in _site_dirs():
        found += sorted(d.glob("hexbench[-_]attack*"))
    found += sorted(p for p in tmp_path.rglob("*") if p.name.startswith(("hexbench-attack", "hexbench_attack")))
    return found


def _remove(paths: list[Path]) -> None:
    for p in paths:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)


def _git_state() -> dict[str, str]:
    """`git status --porcelain` of the repository, each entry with its file's content hash."""
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=REPO,
                         capture_output=True, text=True, timeout=30, check=True).stdout
    state = {}
    for line in out.splitlines():
        path = REPO / line[3:].split(" -> ")[-1].strip('"')
        try:
            digest = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "-"
        except OSError:
            digest = "?"
        state[line] = digest
    return state


def _ancestors() -> set[int]:
    pids, pid = set(), os.getpid()
    while pid > 1:
        pids.add(pid)
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            break
    return pids


def _stragglers(needles: list[str], pgid: int) -> dict[int, str]:
    """Live processes (not this one or its ancestors) whose command line holds a needle or which
    are in the run's process group."""
    mine = _ancestors()
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) in mine:
            continue
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if fields[0] == "Z" or not cmd:
            continue
        if any(n in cmd for n in needles) or int(fields[2]) == pgid:
            found[int(entry.name)] = cmd.strip()
    return found


def _kill(pids) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


# ------------------------------------------------------------------------------- the servers
class _Listeners:
    """A TCP server on 127.0.0.1 (ephemeral port) and an abstract Unix socket; counts accepts."""

    def __init__(self):
        self.tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.tcp.bind(("127.0.0.1", 0))
        self.tcp.listen(8)
        self.port = self.tcp.getsockname()[1]
        self.unix = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.unix.bind(f"\0hexbench-attack-socket-{self.port}")
        self.unix.listen(8)
        self.accepted: list[str] = []
        self._stop = False
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        socks = {self.tcp: "tcp", self.unix: "unix"}
        while not self._stop:
            ready, _, _ = select.select(list(socks), [], [], 0.1)
            for s in ready:
                conn, _ = s.accept()
                self.accepted.append(socks[s])
                conn.close()

    def close(self) -> None:
        self._stop = True
        self._thread.join(5)
        self.tcp.close()
        self.unix.close()


# ---------------------------------------------------------------------------------- the runs
def _controller_file(name: str, tmp_path: Path, listeners: _Listeners | None, copy: bool,
                     sparse_files: tuple[tuple[str, int], ...] = ()) -> Path:
    """The file to run: the corpus file, or a copy in tmp_path (with the test server's port and
    the sparse files its case asks for beside it)."""
    src = CONTROLLERS / f"{name.split('@')[0]}.py"
    if listeners is None and not copy and not sparse_files:
        return src
    text = src.read_text()
    if listeners is not None:
        assert "\nPORT = 0\n" in text
        text = text.replace("\nPORT = 0\n", f"\nPORT = {listeners.port}\n", 1)
    copy = tmp_path / "work" / src.name
    copy.parent.mkdir()
    copy.write_text(text)
    for file_name, size_bytes in sparse_files:
        with open(copy.parent / file_name, "wb") as f:
            f.truncate(size_bytes)
    return copy


def _run(args: list[str], tmp_path: Path, timeout_s: float):
    out_log, err_log = tmp_path / "stdout.txt", tmp_path / "stderr.txt"
    t0 = time.monotonic()
    with open(out_log, "w") as out, open(err_log, "w") as err:
        proc = subprocess.Popen(args, cwd=REPO, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                                start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            rc = None
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except OSError:
                pass
            proc.wait(10)
    return rc, time.monotonic() - t0, proc.pid, out_log.read_text(errors="replace"), err_log.read_text(errors="replace")


def _check_honest_record(path: Path, controller: Path) -> list[str]:
    problems = []
    if not path.is_file():
        return [f"exit 0 but no {path}"]
    rec = json.loads(path.read_text())
    eps = rec.get("episodes", [])
    if len(eps) != 1 or (eps[0].get("terrain"), eps[0].get("level")) != ("stairs", 8.0):
        problems.append(f"record episodes are not the one stairs-8 episode: {eps}")
    if any(e.get("success") or e.get("end_reason") == "success" for e in eps):
        problems.append(f"FORGED SUCCESS: {eps}")
    if any(lv.get("successes") for lv in rec.get("levels", [])):
        problems.append(f"FORGED SUCCESS in levels: {rec.get('levels')}")
    sha = hashlib.sha256(controller.read_bytes()).hexdigest()
    if rec.get("controller", {}).get("sha256") != sha:
        problems.append(f"record names sha256 {rec.get('controller', {}).get('sha256')}, the file's is {sha}")
    return problems


def test_every_attack_file_has_a_case_and_a_docstring():
    files = sorted(CONTROLLERS.glob("attack_*.py"))
    assert {f.stem for f in files} == {name.split("@")[0] for name in CASES}
    assert len(files) >= 18
    for f in files:
        doc = ast.get_docstring(ast.parse(f.read_text()))
        assert doc and "honest evaluator must" in doc.replace("\n", " "), f"{f.name}: docstring says what is attacked and what an honest evaluator must do"


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.timeout(CASES[n].max_s + 90)]
                                                   + ([pytest.mark.slow] if CASES[n].slow else [])) for n in sorted(CASES)])
def test_attack_is_contained(name, tmp_path):
    case = CASES[name]
    if case.needs_bwrap and not HAVE_BWRAP:
        pytest.skip("needs bubblewrap (bwrap) to be contained")
    if case.needs_landlock and not landlock_abi():
        pytest.skip("needs Landlock (Linux 5.13+, py-landlock) to be contained under --isolation process")
    timeout_s = case.max_s + 30.0
    _remove(_attack_files(tmp_path))  # left over from an earlier run
    git_before = _git_state()
    listeners = _Listeners() if name.split("@")[0] == "attack_socket" else None
    problems: list[str] = []
    try:
        controller = _controller_file(name, tmp_path, listeners, bool(case.out) or case.seed_key or case.link_outside,
                                      case.sparse_files)
        if case.link_outside:
            not_shown = tmp_path / "not-shown"
            not_shown.mkdir()
            (not_shown / "secret.txt").write_text("not for the controller")
            (controller.parent / "outside").symlink_to(not_shown)
        out_dir = {"": tmp_path / "out", "runs": controller.parent / "runs" / f"{controller.stem}-v1",
                   "same": controller.parent}[case.out]
        files = [str(controller)] + ([str(CPG)] if case.then_cpg else [])
        key_args: list[str] = []
        if case.seed_key:  # inside the controller's own folder: the sandbox must cover it up there too
            key = controller.parent / "seed.key"
            key.write_bytes(b"hexbench red-team seed key, 32+ bytes long")
            key.chmod(0o644)
            key_args = ["--seed-key", str(key)]
        args = [sys.executable, "-m", "hexbench", "run", *files, "--terrain", "stairs", "--levels", "8",
                "--episodes", "1", "--workers", "1", "--no-record", "--out", str(out_dir), *key_args, *case.extra_args]
        rc, wall_s, pgid, stdout, stderr = _run(args, tmp_path, timeout_s)
    finally:
        if listeners is not None:
            time.sleep(0.2)
            listeners.close()
    command = " ".join(args)

    # the outcome
    result = out_dir / controller.stem / "result.json" if case.then_cpg else out_dir / "result.json"
    if rc is None:
        problems.append(f"did not finish within {timeout_s:.0f} s (killed)")
    elif wall_s > case.max_s:
        problems.append(f"took {wall_s:.1f} s; at most {case.max_s:.0f} s allowed")
    for stream, text in (("stdout", stdout), ("stderr", stderr)):
        if "Traceback" in text:
            problems.append(f"a traceback on {stream}")
        if OUTPUT_MARKER in text:
            problems.append(f"the controller's own text reached the evaluator's {stream}")
        control = sorted(set(CONTROL_CHARS.findall(text)))
        if control:
            problems.append(f"control characters (terminal escapes) on {stream}: {control}")
    if rc == 0:
        if case.expect == ERROR:
            problems.append("exit 0; this attack must stop the run with an error")
        problems += _check_honest_record(result, controller)
    elif rc == 1:
        if case.expect == HONEST:
            problems.append("exit 1; this attack must be contained and scored honestly (exit 0)")
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        if len(lines) != 1:
            problems.append(f"stderr holds {len(lines)} lines; expected exactly one error line")
        if not lines or not lines[0].startswith("error: ") or controller.name not in lines[0]:
            problems.append(f"stderr's first line is not 'error: ...' naming {controller.name}")
        elif case.error_words and not any(w in lines[0].lower() for w in case.error_words):
            problems.append(f"the error line names none of {case.error_words}")
        if lines and "no such controller file" in lines[0]:
            problems.append("the evaluator could not see the controller file (it exists): the attack was not tried")
        if result.exists():
            problems.append(f"exit 1 but {result} was written")
    elif rc is not None:
        problems.append(f"exit status {rc}; expected 0 or 1")
    if case.then_cpg:
        problems += [f"baselines/cpg.py after it: {p}" for p in _check_honest_record(out_dir / "cpg" / "result.json", CPG)]

    # what it left behind
    needles = [MARKER, str(controller), str(tmp_path)]
    left = _stragglers(needles, pgid)
    for _ in range(20):  # a process that is being torn down gets a moment to go
        if not left:
            break
        time.sleep(0.1)
        left = _stragglers(needles, pgid)
    if left:
        _kill(left)
        problems.append(f"processes left running: {left}")
    planted = _attack_files(tmp_path)
    if planted:
        _remove(planted)
        problems.append(f"files written outside the controller's process: {[str(p) for p in planted]}")
    git_after = _git_state()
    if git_after != git_before:
        changed = sorted(set(git_after.items()) ^ set(git_before.items()))
        problems.append(f"`git status` of the repository changed: {changed}")
    if listeners is not None and listeners.accepted:
        problems.append(f"the controller reached the test's servers: {listeners.accepted}")

    verdict = ("killed at the deadline" if rc is None else f"record: {result.name} written" if rc == 0
               else next((ln for ln in stderr.splitlines() if ln.strip()), ""))
    print(f"{name}: exit {rc} after {wall_s:.1f} s: {verdict[:300]}")  # shown with -rP
    assert not problems, (f"{name}: {command}\n  exit {rc} after {wall_s:.1f} s\n  " + "\n  ".join(problems)
                          + f"\n--- stderr (tail) ---\n{stderr[-1500:]}\n--- stdout (tail) ---\n{stdout[-800:]}")
