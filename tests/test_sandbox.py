"""The controller sandbox: what a controller process sees, its deadlines, and its end."""

import json
import os
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from typer.testing import CliRunner

from hexbench.cli import app
from hexbench.evaluation import sandbox
from hexbench.evaluation.episode import EpisodeJob, run_episode
from hexbench.evaluation.evaluate import evaluate
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
CPG = str(REPO / "baselines" / "cpg.py")
needs_bwrap = pytest.mark.skipif(sandbox.bubblewrap_version() is None, reason="bubblewrap is not usable here")


def controller(tmp_path, body: str, name: str = "probe.py") -> str:
    """A controller file: the open-loop CPG plus `body` run in make_controller (task in scope) and act."""
    path = tmp_path / name
    path.write_text(textwrap.dedent('''
        import numpy as np
        class Probe:
            action_mode = "cpg_residual"
            def __init__(self, task):
                self.task = task
            def reset(self, seed):
                self.seed = seed
            def act(self, obs):
                check(self)
                return np.zeros(18, dtype=np.float32)
        def make_controller(task):
            return Probe(task)
        ''') + textwrap.dedent(body))
    return str(path)


def short_job(path: str, isolation: str = "auto", steps: int = 5, **kw) -> EpisodeJob:
    task = load_suite("v1").task("stairs", 2)
    return EpisodeJob(path, task, 0, task.seeds(1)[0], max_steps=steps,
                      isolation=sandbox.resolve_isolation(isolation), **kw)


def live_descendants() -> dict[int, psutil.Process]:
    return {p.pid: p for p in psutil.Process().children(recursive=True)
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE}


@pytest.fixture
def processes_started_here():
    """Lists the processes started during the test that are still alive. Processes that were already
    running (the resource tracker of an earlier test's process pool lives as long as pytest) do not count."""
    before = set(live_descendants())
    return lambda: [p for pid, p in live_descendants().items() if pid not in before]


@pytest.fixture(autouse=True)
def _stop_controllers():
    yield
    sandbox.close_all()


@needs_bwrap
def test_the_controller_sees_only_a_scratch_folder_a_clean_environment_and_no_network(tmp_path, monkeypatch):
    monkeypatch.setenv("HEXBENCH_SECRET_MARKER", "leaked")
    path = controller(tmp_path, '''
        import os, socket
        from pathlib import Path
        def check(self):
            assert "HEXBENCH_SECRET_MARKER" not in os.environ, "parent environment leaked"
            assert os.getcwd() == "/scratch", os.getcwd()
            Path("scratch-file").write_text("mine")  # the scratch folder is writable
            for folder in ("/work/main/runs", "/root", str(Path.home()) + "/.ssh"):
                assert not Path(folder, "x").exists()
            try:
                Path(__file__).with_name("planted.txt").write_text("x")
            except OSError:
                pass
            else:
                raise AssertionError("the controller's folder is writable")
            try:
                socket.create_connection(("127.0.0.1", 9), timeout=0.2)
            except OSError:
                pass
            else:
                raise AssertionError("network reachable")
            assert os.getuid() == 65534
        ''')
    row = run_episode(short_job(path, "bubblewrap"))
    assert row["steps"] == 5
    assert not (tmp_path / "planted.txt").exists() and not Path("scratch-file").exists()


@pytest.mark.parametrize("isolation", ["auto", "process"])
def test_the_controller_multiplies_with_the_same_kernel_on_every_cpu(tmp_path, isolation):
    """oneMKL picks its float32 kernel by CPU unless capped; the controller process is capped before
    it multiplies anything (hexbench.suite.numerics), so a policy's actions are the same bits on an
    AVX-512 Intel and an AMD machine (tests/test_golden.py replays episodes recorded on AMD)."""
    path = controller(tmp_path, '''
        import os
        def check(self):
            assert os.environ.get("MKL_ENABLE_INSTRUCTIONS") == "SSE4_2", os.environ.get("MKL_ENABLE_INSTRUCTIONS")
            assert os.environ.get("OMP_NUM_THREADS") == "1"
        ''')
    assert run_episode(short_job(path, isolation, steps=2))["steps"] == 2


def test_reset_gets_a_derived_seed_never_the_episode_seed(tmp_path):
    path = controller(tmp_path, '''
        def check(self):
            assert self.seed not in self.task.seeds(), "reset() was given a protocol episode seed"
        ''')
    task = load_suite("v1").task("stairs", 2)
    job = EpisodeJob(path, task, 0, task.seeds(1)[0], max_steps=3, secret_hex="ab" * 32)
    assert run_episode(job)["steps"] == 3


@pytest.mark.parametrize("isolation", ["auto", "process"])
@pytest.mark.parametrize("body, expected", [
    ("import time\ndef check(self):\n    end = time.monotonic() + 30\n    while time.monotonic() < end:\n        pass\n",
     "act() took longer than 1 s of CPU time at step 0"),
    ("import os\ndef check(self):\n    os._exit(0)\n", "exited with code 0 at step 0"),
    ("import ctypes\ndef check(self):\n    ctypes.string_at(0)\n", "crashed (SIGSEGV) at step 0"),
    ("import os\ndef check(self):\n    os.fork()\n", "act() raised PermissionError at step 0"),
])
def test_abnormal_ends_are_one_line_and_leave_no_process(tmp_path, body, expected, isolation,
                                                         processes_started_here):
    if isolation == "process" and not sandbox.seccomp_available() and "fork" in body:
        pytest.skip("no seccomp here")
    path = controller(tmp_path, body)
    with pytest.raises(sandbox.ControllerError) as err:
        run_episode(short_job(path, isolation))
    message = str(err.value)
    assert expected in message and path in message and "\n" not in message
    sandbox.close_all()
    assert processes_started_here() == []


def test_a_waiting_controller_is_stopped_by_the_wall_time_limit_and_a_busy_machine_fails_no_one(tmp_path):
    """act() may use 1 s of CPU time; one that sleeps is stopped after call_wall_timeout_s of wall time."""
    sleeper = controller(tmp_path, "import time\ndef check(self):\n    time.sleep(60)\n")
    with pytest.raises(sandbox.ControllerError, match=r"act\(\) took longer than 3 s at step 0"):
        process = sandbox.ControllerProcess(sleeper, sandbox.resolve_isolation("auto"),
                                            sandbox.Limits(call_wall_timeout_s=3.0))
        try:
            ctrl = process.controller_for(load_suite("v1").task("stairs", 2))
            ctrl.reset(0)
            ctrl.act(np.zeros(62, np.float32), 0)
        finally:
            process.close()
    # a short wait (1.5 s of wall time, no CPU) is within the limits
    napper = controller(tmp_path, "import time\ndef check(self):\n    time.sleep(1.5)\n", name="napper.py")
    assert run_episode(short_job(napper, steps=2))["steps"] == 2


def _act_steps(path: str, limits: "sandbox.Limits", steps: int) -> None:
    process = sandbox.ControllerProcess(path, sandbox.resolve_isolation("auto"), limits)
    try:
        ctrl = process.controller_for(load_suite("v1").task("stairs", 2))
        ctrl.reset(0)
        for step in range(steps):
            ctrl.act(np.zeros(62, np.float32), step)
    finally:
        process.close()


@pytest.mark.parametrize("nap_s, stopped_by_step", [(0.3, 6), (0.02, 70)])
def test_a_controller_that_keeps_waiting_is_stopped_by_the_waiting_budget(tmp_path, nap_s, stopped_by_step,
                                                                            processes_started_here):
    """Each nap is within the per-call limits (1 s of CPU, 10 s of wall time), but all together they
    pass the waiting budget (counted whenever the calls since the last count took 50 ms)."""
    if not sandbox.SCHEDULER_COUNTERS:
        pytest.skip("no per-thread scheduler counters here: waiting is not counted")
    napper = controller(tmp_path, f"import time\ndef check(self):\n    time.sleep({nap_s})\n")
    limits = sandbox.Limits(wait_budget_s=1.0)
    with pytest.raises(sandbox.ControllerError, match=r"act\(\) waited without computing .* beyond the 1 s "
                                                      r"a controller may .* at step (\d+) \(controller process killed\)") as err:
        _act_steps(napper, limits, 200)
    assert int(err.value.args[0].split("at step ")[1].split()[0]) < stopped_by_step
    assert "\n" not in str(err.value)
    assert processes_started_here() == []


def test_make_controller_after_start_up_counts_its_waiting(tmp_path):
    """Start-up (imports, the first make_controller) may wait; a later make_controller that sleeps
    is counted, so that 43 tasks cannot each cost make_timeout_s."""
    if not sandbox.SCHEDULER_COUNTERS:
        pytest.skip("no per-thread scheduler counters here: waiting is not counted")
    path = tmp_path / "slow_make.py"
    path.write_text("import time\nimport numpy as np\nMADE = []\n"
                    "class C:\n    action_mode = 'cpg_residual'\n    def reset(self, seed):\n        pass\n"
                    "    def act(self, obs):\n        return np.zeros(18, dtype=np.float32)\n"
                    "def make_controller(task):\n    time.sleep(1.5)\n    MADE.append(task)\n    return C()\n")
    process = sandbox.ControllerProcess(str(path), sandbox.resolve_isolation("auto"), sandbox.Limits(wait_budget_s=1.0))
    suite = load_suite("v1")
    try:
        process.controller_for(suite.task("stairs", 2))  # start-up: 1.5 s of sleep, not counted
        with pytest.raises(sandbox.ControllerError, match=r"make_controller waited without computing .* for stairs"):
            process.controller_for(suite.task("stairs", 4))
    finally:
        process.close()


def test_a_controller_that_computes_is_not_charged_for_waiting(tmp_path):
    """A controller busy for 30 ms per call (longer than the calls counted at once) and one with
    sub-millisecond calls both play 200 steps on a waiting budget of 0.2 s."""
    if not sandbox.SCHEDULER_COUNTERS:
        pytest.skip("no per-thread scheduler counters here: waiting is not counted")
    limits = sandbox.Limits(wait_budget_s=0.2)
    busy = controller(tmp_path, "import time\ndef check(self):\n    end = time.thread_time() + 0.03\n"
                                "    while time.thread_time() < end:\n        pass\n", name="busy.py")
    _act_steps(busy, limits, 200)
    _act_steps(CPG, limits, 200)


def test_make_controller_has_a_deadline_enforced_from_outside(tmp_path, processes_started_here):
    path = tmp_path / "hang.py"
    path.write_text("import time\ndef make_controller(task):\n    while True:\n        time.sleep(1)\n")
    with pytest.raises(sandbox.ControllerError, match="make_controller took longer than 3 s"):
        run_episode(short_job(str(path), make_timeout_s=3.0))
    assert processes_started_here() == []


def test_memory_is_limited(tmp_path):
    path = controller(tmp_path, "def check(self):\n    self.hog = bytearray(6 << 30)\n")
    with pytest.raises(sandbox.ControllerError, match="MemoryError at step 0"):
        run_episode(short_job(path))


def test_sandboxed_and_in_process_episodes_are_identical_and_records_name_the_isolation(tmp_path):
    tasks = [load_suite("v1").task("rough", 3)]
    a = evaluate(CPG, tasks, tmp_path / "a", episodes=1, workers=1, record=False, progress=False)
    b = evaluate(CPG, tasks, tmp_path / "b", episodes=1, workers=1, record=False, progress=False, isolation="none")
    assert a.record["episodes"] == b.record["episodes"]
    assert a.record["provenance"]["isolation"]["sandboxed"] is True
    assert b.record["provenance"]["isolation"] == {"mode": "none", "sandboxed": False}


def test_unknown_isolation_and_missing_files_are_one_line(tmp_path):
    runner = CliRunner()
    bad = runner.invoke(app, ["run", CPG, "--isolation", "docker", "--out", str(tmp_path / "o")])
    assert bad.exit_code == 2 and "valid: auto, bubblewrap, process, none" in bad.output
    res = runner.invoke(app, ["run", str(tmp_path / "missing.py"), CPG, "--terrain", "stairs", "--levels", "2",
                              "--episodes", "1", "--workers", "1", "--no-record", "--out", str(tmp_path / "o")])
    assert res.exit_code == 1 and "missing.py: no such controller file" in res.output
    assert (tmp_path / "o" / "cpg" / "result.json").is_file()  # the other file still ran
    folder = runner.invoke(app, ["check", str(tmp_path)])
    assert folder.exit_code == 1 and "is a folder; expected a controller file" in folder.output
    assert "Traceback" not in folder.output + res.output


def test_a_pipe_or_a_huge_controller_file_is_one_line_and_the_others_still_run(tmp_path):
    """The evaluator hashes a controller file before anything runs: a pipe would make that wait
    forever, a huge sparse file read for hours. Each is one line; the file after them still runs."""
    from hexbench.suite.controller import MAX_CONTROLLER_FILE_BYTES

    pipe, huge = tmp_path / "pipe.py", tmp_path / "huge.py"
    os.mkfifo(pipe)
    with open(huge, "wb") as f:
        f.truncate(MAX_CONTROLLER_FILE_BYTES + 1)
    t0 = time.monotonic()
    res = CliRunner().invoke(app, ["run", str(pipe), str(huge), CPG, "--terrain", "stairs", "--levels", "2",
                                   "--episodes", "1", "--workers", "1", "--no-record", "--out", str(tmp_path / "o")])
    assert time.monotonic() - t0 < 60
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error: ")]
    assert res.exit_code == 1 and len(errors) == 2, res.output
    assert "pipe.py: is a pipe; expected a controller file" in errors[0] and "huge.py: 16,777,217 bytes" in errors[1]
    assert (tmp_path / "o" / "cpg" / "result.json").is_file()
    assert not (tmp_path / "o" / "pipe").exists() and not (tmp_path / "o" / "huge").exists()


@pytest.mark.parametrize("make_out", ["file", "readonly", "long"])
def test_unwritable_outputs_are_one_line_and_leave_nothing(tmp_path, make_out):
    if make_out == "file":
        out = tmp_path / "out"
        out.write_text("not a folder")
        expect = "exists and is not a folder"
    elif make_out == "readonly":
        if os.geteuid() == 0:
            out = Path("/proc/hexbench-out")  # root ignores permission bits; /proc refuses everyone
        else:
            (tmp_path / "ro").mkdir(mode=0o500)
            out = tmp_path / "ro" / "out"
        expect = "cannot create the folder"
    else:
        out = tmp_path / ("x" * 300)
        expect = "file name too long"
    res = CliRunner().invoke(app, ["run", CPG, "--terrain", "stairs", "--levels", "2", "--episodes", "1",
                                   "--workers", "1", "--no-record", "--out", str(out)])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1 and expect in lines[0], res.output
    assert "Traceback" not in res.output


NOISY = """
import numpy as np

class Noisy:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.rng = np.random.default_rng(seed)

    def act(self, obs):  # small random residuals: an action log that does not compress
        return self.rng.uniform(-0.05, 0.05, 18).astype(np.float32)

def make_controller(task):
    return Noisy()
"""


@pytest.mark.parametrize("what_fills_it", ["action logs", "recording"])
def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, what_fills_it, small_disk):
    """A run onto a small file system (a tmpfs): the write that finds the disk full, whichever it
    is (an episode's action log in the evaluator; its MCAP or .rrd in a pool worker), is one line,
    and the run leaves no file."""
    import subprocess

    disk = tmp_path / "disk"
    size_bytes = 64 << 10 if what_fills_it == "action logs" else 1 << 20
    prefix = small_disk(disk, size_bytes)
    if what_fills_it == "action logs":
        (tmp_path / "noisy.py").write_text(NOISY)
        args = [str(tmp_path / "noisy.py"), "--workers", "1", "--no-record"]
    else:
        args = [CPG, "--workers", "2"]
    run = " ".join([sys.executable, "-m", "hexbench", "run", *args, "--terrain", "stairs", "--levels", "2",
                    "--episodes", "4", "--isolation", "process", "--out", str(disk / "out")])
    shown = subprocess.run([*prefix, "sh", "-c", f"{run}; echo rc=$?; find {disk} -mindepth 1"], cwd=REPO,
                           capture_output=True, text=True, timeout=300)
    lines = shown.stdout.splitlines()
    assert "rc=1" in lines, shown.stdout + shown.stderr
    assert lines[lines.index("rc=1") + 1:] == []  # nothing left on the disk
    errors = [ln for ln in shown.stderr.splitlines() if ln.startswith("error: ")]
    assert len(errors) == 1 and errors[0].endswith(": cannot be written (no space left on device)"), shown.stderr
    assert "Traceback" not in shown.stderr


def test_a_full_temporary_folder_is_one_line_and_leaves_nothing(tmp_path, small_disk):
    """The evaluator writes the robot's URDF to the temporary folder (PyBullet loads files only)."""
    import subprocess

    prefix = small_disk(Path(tempfile.gettempdir()), 4096)
    check = f"{sys.executable} -m hexbench check {CPG} --steps 3 --isolation process"
    shown = subprocess.run([*prefix, "sh", "-c", f"{check}; echo rc=$?; find {tempfile.gettempdir()} -mindepth 1"],
                           cwd=REPO, capture_output=True, text=True, timeout=120)
    assert shown.stdout.splitlines() == ["rc=1"], shown.stdout + shown.stderr
    errors = [ln for ln in shown.stderr.splitlines() if ln.strip()]
    assert len(errors) == 1 and errors[0].endswith(": cannot write the robot's URDF (no space left on device)"), errors


def test_a_controller_process_folder_that_cannot_be_made_is_one_line(tmp_path, monkeypatch):
    import errno
    from types import SimpleNamespace

    from hexbench.errors import OutputError

    def no_space(prefix):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(sandbox, "tempfile", SimpleNamespace(mkdtemp=no_space, gettempdir=lambda: "/tmp"))
    with pytest.raises(OutputError, match=r"^/tmp: cannot make the folder of .*cpg.py's controller process "
                                          r"\(no space left on device\)$"):
        sandbox.ControllerProcess(CPG, "process")


def test_a_failing_run_into_an_existing_folder_keeps_the_earlier_runs_files(tmp_path):
    out = tmp_path / "out"
    tasks = [load_suite("v1").task("stairs", 2)]
    assert evaluate(CPG, tasks, out, episodes=1, workers=1, record=False, progress=False).error is None
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    bad = controller(tmp_path, "def check(self):\n    raise RuntimeError('boom')\n", name="cpg.py")
    res = evaluate(bad, tasks, out, episodes=1, workers=1, record=False, progress=False)
    assert res.error and "boom" in res.error
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    assert json.loads((out / "result.json").read_text())["label"] == "cpg"


@needs_bwrap
def test_the_run_folder_the_seed_key_and_the_working_directory_stay_hidden(tmp_path, monkeypatch):
    """Even when the run folder and the key file sit inside the controller's own (visible) folder."""
    monkeypatch.chdir(REPO)
    key = tmp_path / "seed.key"
    key.write_bytes(b"s" * 32)
    path = controller(tmp_path, f'''
        from pathlib import Path
        def check(self):
            out = Path(__file__).with_name("out")
            assert list((out / ".journal").iterdir()) == [], "the run secret is visible"
            assert list((out / "episodes").iterdir()) == [], "the action logs are visible"
            try:
                leaked = Path("{key}").read_bytes()
            except OSError:
                leaked = b""
            assert leaked == b"", "the seed key is visible"
            assert not Path("{REPO / 'leaderboard' / 'README.md'}").exists(), "the working directory is visible"
        ''')
    res = CliRunner().invoke(app, ["run", path, "--terrain", "stairs", "--levels", "2", "--episodes", "1",
                                   "--workers", "1", "--no-record", "--out", str(tmp_path / "out"),
                                   "--seed-key", str(key), "--isolation", "bubblewrap"])
    assert res.exit_code == 0, res.output



@pytest.mark.parametrize("isolation", ["auto", "process"])
def test_the_controller_process_runs_the_evaluators_own_hexbench(tmp_path, isolation):
    """An evaluator imported from another checkout than the installed hexbench (a second worktree
    on PYTHONPATH) runs its controller host from that checkout too, and only that package is
    visible to the sandbox."""
    import shutil
    import subprocess
    import sys

    checkout = tmp_path / "checkout"
    shutil.copytree(REPO / "hexbench", checkout / "hexbench", ignore=shutil.ignore_patterns("__pycache__"))
    path = controller(tmp_path, f'''
        import hexbench
        from pathlib import Path
        def check(self):
            assert Path(hexbench.__file__).parent == Path({str(checkout / "hexbench")!r}), hexbench.__file__
        ''')
    script = textwrap.dedent(f'''
        import hexbench
        from hexbench.evaluation import sandbox
        from hexbench.evaluation.episode import EpisodeJob, run_episode
        from hexbench.suite.tasks import load_suite
        assert hexbench.__file__.startswith({str(checkout)!r}), hexbench.__file__
        task = load_suite("v1").task("stairs", 2)
        job = EpisodeJob({path!r}, task, 0, task.seeds(1)[0], max_steps=2,
                         isolation=sandbox.resolve_isolation({isolation!r}))
        print("steps", run_episode(job)["steps"])
        sandbox.close_all()
        ''')
    env = {**os.environ, "PYTHONPATH": str(checkout), "HEXBENCH_TASKS_DIR": str(REPO / "tasks")}
    done = subprocess.run([sys.executable, "-c", script], env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "steps 2" in done.stdout


@pytest.mark.skipif(os.geteuid() != 0, reason="capabilities are root's to drop")
def test_a_root_controller_process_that_stays_root_keeps_no_capability():
    """Under --isolation process a root evaluator whose Python nobody can read starts the controller
    as root: with an empty bounding set its exec grants it no capability (no reading other users'
    files, no tracing, no memory of a process that is not dumpable)."""
    import subprocess
    import sys

    from hexbench.evaluation.isolation import DEFAULT_LIMITS, preexec_for

    status = subprocess.run([sys.executable, "-c", "print(open('/proc/self/status').read())"], capture_output=True,
                            text=True, check=True, preexec_fn=preexec_for(DEFAULT_LIMITS, False, True, True)).stdout
    caps = {line.split(":")[0]: int(line.split(":")[1], 16) for line in status.splitlines() if line.startswith("Cap")}
    assert caps["CapEff"] == caps["CapPrm"] == caps["CapBnd"] == caps["CapAmb"] == 0, caps
    assert "Uid:\t0\t0\t0\t0" in status  # still root, without the power of root


def test_the_controller_host_refuses_to_set_up_its_sandbox_with_other_threads_running():
    """seccomp and Landlock bind the thread that installs them: a thread started earlier would run
    unfiltered, so the host refuses to go on, as one error message."""
    import subprocess
    import sys

    code = textwrap.dedent("""
        import os, threading, time
        from hexbench.evaluation import controller_host, wire
        threading.Thread(target=time.sleep, args=(10,), daemon=True).start()
        to_host_r, to_host_w = os.pipe()
        from_host_r, from_host_w = os.pipe()
        controller_host.main(["host", str(to_host_r), str(from_host_w), "on", "off"])
        kind, payload = wire.Inbox(from_host_r).recv()
        print(kind.decode(), payload.decode())
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO).stdout
    assert out.startswith("E ") and "threads before its sandbox is set up" in out, out


@pytest.mark.parametrize("isolation", ["auto", "process"])
def test_a_controller_ends_at_once_when_the_run_is_over(tmp_path, isolation, processes_started_here):
    """After QUIT the controller process ends without the interpreter's teardown: neither its own
    atexit handlers nor a slow teardown (a torch controller's took 0.6 s) hold up the end of a run."""
    path = controller(tmp_path, "import atexit, time\natexit.register(time.sleep, 30)\ndef check(self):\n    pass\n")
    row = run_episode(short_job(path, isolation))
    assert row["steps"] == 5
    start = time.monotonic()
    sandbox.close_all()
    assert time.monotonic() - start < 1.0  # the grace period alone is 2 s
    assert processes_started_here() == []


@pytest.mark.parametrize("where, body, problem", [
    ("make_controller", "import os\nfor i in range(5):\n    with open(f'big-{i}', 'wb') as f:\n"
                        "        f.write(bytes(60 << 20))\ndef check(self):\n    pass\n",
     "wrote more than 256 MiB to its scratch folder"),
    ("act", "import os\ndef check(self):\n    self.n = getattr(self, 'n', 0) + 1\n    os.makedirs(str(self.n))\n"
            "    for i in range(100):\n        open(f'{self.n}/{i}', 'w').close()\n",
     "made more than 10,000 files and folders in its scratch folder"),
    ("deleted while open", "import os\nheld = []\nfor i in range(5):\n    held.append(open(f'big-{i}', 'wb'))\n"
                           "    held[-1].write(bytes(60 << 20))\n    held[-1].flush()\n    os.remove(f'big-{i}')\n"
                           "def check(self):\n    pass\n",
     "wrote more than 256 MiB to its scratch folder"),
])
def test_a_controller_that_outgrows_its_scratch_folder_on_disk_is_stopped(tmp_path, where, body, problem,
                                                                          processes_started_here):
    """Under process isolation the scratch folder is on the evaluator's disk: its size and number of
    entries are bounded as bubblewrap's tmpfs is (256 MiB), and the folder is gone with the process."""
    before = set(Path(tempfile.gettempdir()).glob(f"{sandbox.SANDBOX_FOLDER_PREFIX}{os.getpid()}-*"))
    path = controller(tmp_path, body)
    with pytest.raises(sandbox.ControllerError, match=problem) as failure:
        run_episode(short_job(path, "process", steps=400))
    assert "\n" not in str(failure.value)
    assert processes_started_here() == []
    assert set(Path(tempfile.gettempdir()).glob(f"{sandbox.SANDBOX_FOLDER_PREFIX}{os.getpid()}-*")) <= before


@pytest.mark.parametrize("isolation", ["auto", "process"])
def test_threads_are_bounded_from_outside(tmp_path, isolation, processes_started_here):
    """No rlimit bounds the threads of a user namespace's root: the evaluator counts them, here after
    make_controller starts 600 (each waiting) and at once in a call that keeps starting them."""
    many = controller(tmp_path, "import threading\nthreading.stack_size(64 << 10)\nstop = threading.Event()\n"
                                "for _ in range(600):\n    threading.Thread(target=stop.wait, daemon=True).start()\n"
                                "def check(self):\n    pass\n", name="many.py")
    with pytest.raises(sandbox.ControllerError, match=r"ran \d+ threads, more than the 256 a controller may"):
        run_episode(short_job(many, isolation))
    slow = controller(tmp_path, "import threading, time\nthreading.stack_size(64 << 10)\nstop = threading.Event()\n"
                                "def check(self):\n    while True:\n"
                                "        threading.Thread(target=stop.wait, daemon=True).start()\n"
                                "        time.sleep(0.001)\n", name="slow.py")
    start = time.monotonic()
    with pytest.raises(sandbox.ControllerError, match=r"threads, more than the 256 a controller may at step 0"):
        run_episode(short_job(slow, isolation))
    assert time.monotonic() - start < 5.0
    assert processes_started_here() == []


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: nothing to pin")
@pytest.mark.parametrize("isolation", ["auto", "process"])
def test_one_worker_runs_its_controller_on_its_own_core(tmp_path, isolation):
    """The controller process the run starts first (before the worker pins itself) is pinned along:
    evaluator and controller take turns on one core, with one worker as with several."""
    path = controller(tmp_path, "import os\ndef check(self):\n    assert len(os.sched_getaffinity(0)) == 1, "
                                "sorted(os.sched_getaffinity(0))\n")
    result = evaluate(path, [load_suite("v1").task("stairs", 2)], tmp_path / "run", episodes=1, workers=1,
                      record=False, progress=False, isolation=isolation, max_steps=5)
    assert result.error is None, result.error
