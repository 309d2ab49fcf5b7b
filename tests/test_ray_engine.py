"""hexbench run --engine ray: a real two-node Ray cluster on 127.0.0.1 gives the local engine's record,
also when one node dies mid-run, and trains a two-seed batch; without Ray, one line and exit 2.

The cluster is made here (`ray start --head` + `ray start --address`, one CPU each, private temp
folder, free ports, a token of its own) and torn down by process id: every process whose command
line names the private folder, and their children. `ray stop --force` is not used: it stops every
Ray process on the machine, not only this test's.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from importlib.util import find_spec
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hexbench.cli import app

REPO = Path(__file__).resolve().parent.parent
CPG = "baselines/cpg.py"  # relative: the Ray tasks change into the driver's folder, as on a real cluster
BIN = Path(sys.executable).parent
EPISODES = ["--episodes", "3"]  # tiny protocol: 3 terrains x 1 level x 3 episodes of 40 steps
pytestmark = pytest.mark.timeout(600)  # a cluster test that hangs fails, and the fixture still stops the cluster
needs_ray = pytest.mark.skipif(find_spec("ray") is None or find_spec("psutil") is None,
                               reason="Ray is not installed (pip install 'hexbench[ray]'); psutil (test extra) needed")


def test_engine_ray_without_ray_is_one_line_and_exit_2(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    out = tmp_path / "out"
    r = CliRunner().invoke(app, ["run", str(REPO / CPG), "--engine", "ray", "--out", str(out), "--episodes", "1"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "pip install 'hexbench[ray]'" in lines[0], lines
    assert not out.exists()


def test_unknown_engine_and_address_without_ray_engine(tmp_path):
    r = CliRunner().invoke(app, ["run", str(REPO / CPG), "--engine", "spark", "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and "unknown engine 'spark'; valid: local, ray" in r.stderr
    r = CliRunner().invoke(app, ["run", str(REPO / CPG), "--address", "1.2.3.4:6379", "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and "use it with --engine ray" in r.stderr
    assert not (tmp_path / "x").exists()


@needs_ray
def test_an_unreachable_cluster_is_one_line_and_exit_2(tmp_path):
    r = CliRunner().invoke(app, ["run", str(REPO / CPG), "--engine", "ray", "--address", f"127.0.0.1:{_free_port()}",
                                 "--out", str(tmp_path / "x")])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "cannot reach the Ray cluster at 127.0.0.1:" in lines[0], lines
    assert not (tmp_path / "x").exists()


def test_a_ray_worker_on_a_node_with_a_full_temporary_folder_is_one_line(tmp_path, small_disk):
    """A Ray worker's first task makes its scratch folder in the node's temporary folder: on a disk
    (a tmpfs) that has filled, that is one error naming the folder and the node, and no worker
    folder is left there. The worker's set-up runs in a plain process here: no cluster is needed."""
    disk = tmp_path / "disk"
    prefix = small_disk(disk, 64 << 10)
    script = textwrap.dedent(f"""
        import os
        from pathlib import Path
        from hexbench.errors import HexbenchError
        from hexbench.evaluation import engines
        import tempfile
        tempfile.gettempdir()  # found while the disk had room (Python passes over a full one)
        try:
            with open({str(disk / "filler")!r}, "wb") as f:
                f.write(bytes(1 << 20))
        except OSError:
            pass
        try:
            engines._worker_setup()
        except HexbenchError as e:
            print("error:", e)
        root = Path({str(disk)!r}) / f"hexbench-ray-{{os.getuid()}}"
        print("worker folders left:", sorted(p.name for p in root.iterdir() if p.name != ".lock"))
    """)
    shown = subprocess.run([*prefix, sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                           timeout=120, env={**os.environ, "TMPDIR": str(disk)})
    lines = shown.stdout.splitlines()
    assert lines[:1] == [f"error: {disk}: cannot make a Ray worker's scratch folder on node {socket.gethostname()} "
                         "(no space left on device)"], shown.stdout + shown.stderr
    assert lines[1:] == ["worker folders left: []"]


# ---------------------------------------------------------------------------------- the cluster
# Ports for the cluster come from 20000-32767: above Ray's worker ports (10002-19999 by default) and
# below the kernel's ephemeral range (32768-60999 by default), from which the local end of every
# outgoing connection is drawn, so no connection of the first node takes a port meant for the second.
_CLUSTER_PORTS = (20000, 32768)


def _free_port(port_range: tuple[int, int] | None = None) -> int:
    """A port that binds on 127.0.0.1 now: the kernel's pick, or a random one in [low, high)."""
    for _ in range(200):
        port = 0 if port_range is None else port_range[0] + secrets.randbelow(port_range[1] - port_range[0])
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return s.getsockname()[1]
    raise RuntimeError(f"no free port in {port_range}")


def _node_ports() -> list[str]:
    argv = []
    for option in ("node-manager-port", "object-manager-port", "dashboard-agent-listen-port",
                   "dashboard-agent-grpc-port", "runtime-env-agent-port", "metrics-export-port"):
        argv += [f"--{option}", str(_free_port(_CLUSTER_PORTS))]
    return argv


class Cluster:
    """Two Ray nodes (one CPU each) on 127.0.0.1, in a private temp folder."""

    def __init__(self):
        self.temp = tempfile.mkdtemp(prefix="hxray", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
        self.port = _free_port(_CLUSTER_PORTS)
        self.address = f"127.0.0.1:{self.port}"
        self.env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32),
                    "RAY_USAGE_STATS_ENABLED": "0",
                    # a dead node is declared dead within a few seconds (defaults: tens of seconds)
                    "RAY_health_check_initial_delay_ms": "1000", "RAY_health_check_period_ms": "1000",
                    "RAY_health_check_timeout_ms": "1000", "RAY_health_check_failure_threshold": "3"}
        self.env.pop("RAY_ADDRESS", None)
        common = ["--node-ip-address", "127.0.0.1", "--num-cpus", "1", "--object-store-memory", str(80 << 20),
                  "--disable-usage-stats", "--temp-dir", self.temp]
        self.second_node_manager_port = None
        self._ray("start", "--head", "--port", str(self.port), "--include-dashboard=false",
                  "--dashboard-port", str(_free_port(_CLUSTER_PORTS)), *common, *_node_ports())
        second = _node_ports()
        self.second_node_manager_port = int(second[second.index("--node-manager-port") + 1])
        self._ray("start", "--address", self.address, *common, *second)

    def _ray(self, *args: str) -> None:
        r = subprocess.run([str(BIN / "ray"), *args], env=self.env, capture_output=True, text=True, timeout=180)
        if r.returncode != 0:
            self.stop()
            raise RuntimeError(f"ray {' '.join(args[:2])} failed: {r.stderr[-2000:]}")

    def processes(self):
        """This cluster's processes: those naming its temp folder, and all their descendants."""
        import psutil

        roots = []
        for p in psutil.process_iter(["cmdline"]):
            try:
                if any(self.temp in arg for arg in p.info["cmdline"] or ()):
                    roots.append(p)
            except (psutil.Error, TypeError):
                continue
        found = {p.pid: p for p in roots}
        for p in roots:
            try:
                found.update({c.pid: c for c in p.children(recursive=True)})
            except psutil.Error:
                pass
        return list(found.values())

    def second_raylet(self):
        import psutil

        for p in self.processes():
            try:
                cmd = p.cmdline()
            except psutil.Error:
                continue
            if cmd and cmd[0].endswith("/raylet") and f"--node_manager_port={self.second_node_manager_port}" in cmd:
                return p
        raise AssertionError("the second node's raylet is not running")

    def stop(self) -> None:
        import psutil

        procs = self.processes()
        for p in procs:
            try:
                p.send_signal(signal.SIGKILL)
            except psutil.Error:
                pass
        psutil.wait_procs(procs, timeout=20)
        shutil.rmtree(self.temp, ignore_errors=True)
        # the scratch folders its killed Ray workers left (hexbench.evaluation.engines prunes those of dead workers too)
        root = Path(tempfile.gettempdir()) / f"hexbench-ray-{os.getuid()}"
        for folder in root.glob("[0-9]*"):
            if not psutil.pid_exists(int(folder.name)):
                shutil.rmtree(folder, ignore_errors=True)


def _start_cluster(attempts: int = 3) -> Cluster:
    """A running cluster; a start that fails (a chosen port taken meanwhile by another process) is
    stopped and made again with new ports and a new temp folder."""
    for attempt in range(attempts):
        try:
            return Cluster()
        except RuntimeError:
            if attempt == attempts - 1:
                raise


@pytest.fixture(scope="module")
def cluster():
    c = _start_cluster()
    try:
        yield c
    finally:
        c.stop()
        assert not c.processes()


@pytest.fixture(scope="module")
def module_tiny_protocol(tmp_path_factory):
    """tests/conftest.py's tiny protocol, for the whole module (the cluster and its runs are shared)."""
    from conftest import TINY_PROTOCOL


    folder = tmp_path_factory.mktemp("tiny_tasks_ray")
    (folder / "protocol_v1.toml").write_text(TINY_PROTOCOL)
    old = os.environ.get("HEXBENCH_TASKS_DIR")
    os.environ["HEXBENCH_TASKS_DIR"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("HEXBENCH_TASKS_DIR", None)
    else:
        os.environ["HEXBENCH_TASKS_DIR"] = old


@pytest.fixture(scope="module")
def local_run(module_tiny_protocol, tmp_path_factory):
    """The reference: the same command through the local process pool."""
    out = tmp_path_factory.mktemp("local") / "run"
    r = subprocess.run([str(BIN / "hexbench"), "run", CPG, *EPISODES, "--workers", "2", "--out", str(out)],
                       cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return out


def _with_secret_of(reference: Path, out: Path) -> Path:
    """A fresh run folder holding the reference run's secret (controller seeds come from it)."""
    (out / ".journal").mkdir(parents=True)
    (out / ".journal").chmod(0o700)
    shutil.copy2(reference / ".journal" / "run_secret", out / ".journal" / "run_secret")
    return out


def _ray_run(cluster: Cluster, out: Path) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / "hexbench"), "run", CPG, *EPISODES, "--engine", "ray", "--address",
                             cluster.address, "--out", str(out)], cwd=REPO, env={**cluster.env, "HEXBENCH_TASKS_DIR": os.environ["HEXBENCH_TASKS_DIR"]},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _same_record(local: Path, ray: Path) -> None:
    a, b = (json.loads((p / "result.json").read_text()) for p in (local, ray))
    assert b["episodes"] == a["episodes"]
    assert b["episodes_digest"] == a["episodes_digest"]
    assert a["provenance"]["engine"]["name"] == "local" and b["provenance"]["engine"]["name"] == "ray"
    assert "Ray cluster (2 nodes" in b["provenance"]["engine"]["description"]
    import pandas as pd

    from hexbench.artifacts.files import sha256_file

    # every field, the MCAP hash included; not the .rrd's: Rerun's files differ between any two
    # recordings of the same episode, in one process too (the MCAP is byte-reproducible)
    table_a, table_b = (pd.read_parquet(p / "episodes.parquet").drop(columns="rrd_sha256") for p in (local, ray))
    assert table_b.equals(table_a)
    for row in pd.read_parquet(ray / "episodes.parquet").to_dict("records"):
        for key in ("action_log_path", "mcap_path"):  # the driver wrote the local run's bytes
            assert (ray / "episodes" / row[key]).read_bytes() == (local / "episodes" / row[key]).read_bytes()
        assert sha256_file(ray / "episodes" / row["rrd_path"]) == row["rrd_sha256"]


@needs_ray
def test_ray_cluster_gives_the_local_record(cluster, local_run, tmp_path):
    out = _with_secret_of(local_run, tmp_path / "ray")
    proc = _ray_run(cluster, out)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    assert "on the Ray cluster (2 nodes, 2 CPUs)" in stdout.replace("\n", " ")
    _same_record(local_run, out)
    # the run's Ray workers end with its job, and their sandboxed controller processes with them
    deadline = time.monotonic() + 60
    while _controller_processes(cluster) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert not _controller_processes(cluster)


def _controller_processes(cluster: Cluster) -> list:
    import psutil

    found = []
    for p in cluster.processes():
        try:
            if p.name() == "bwrap" or "hexbench.evaluation.controller_host" in " ".join(p.cmdline()):
                found.append(p.pid)
        except psutil.Error:
            pass
    return found


@needs_ray
def test_a_controller_error_on_the_cluster_is_one_line_and_no_files(cluster, module_tiny_protocol, tmp_path):
    """A controller's error is a result, not a node failure: not retried, the run stops with its line."""
    out = tmp_path / "broken"
    r = subprocess.run([str(BIN / "hexbench"), "run", "tests/controllers/act_raises_at_step_k.py", "--episodes", "1",
                        "--no-record", "--engine", "ray", "--address", cluster.address, "--out", str(out)],
                       cwd=REPO, env={**cluster.env, "HEXBENCH_TASKS_DIR": os.environ["HEXBENCH_TASKS_DIR"]},
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "act_raises_at_step_k.py" in lines[0] \
        and "act() raised ValueError at step 4: policy exploded" in lines[0], lines
    assert not out.exists()


@needs_ray
def test_a_killed_ray_run_resumes_to_the_local_record(cluster, local_run, tmp_path):
    out = _with_secret_of(local_run, tmp_path / "ray-resume")
    proc = _ray_run(cluster, out)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None and len(list((out / ".journal").glob("*.json"))) < 2:
        time.sleep(0.2)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.kill()  # the driver: its Ray job ends, and its workers with it
    proc.communicate(timeout=60)
    kept = {f.name: f.read_text() for f in (out / ".journal").glob("*.json")}
    assert 2 <= len(kept) < 9
    proc = _ray_run(cluster, out)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    _same_record(local_run, out)
    assert all((out / ".journal" / name).read_text() == text for name, text in kept.items())  # taken, not re-run


@needs_ray
def test_a_two_seed_training_batch_completes_on_the_cluster(cluster, tmp_path):
    """`hexbench train --seeds 0-1 --engine ray`: one Ray task per run; runs land in their usual folders."""
    out = tmp_path / "training"
    r = subprocess.run([str(BIN / "hexbench"), "train", "baselines/ppo_cpg.py", "--terrain", "rough", "--seeds", "0-1",
                        "--steps", "2048", "--set", "n_steps=512", "--set", "batch_size=128", "--set", "n_epochs=1",
                        "--checkpoint-every", "5", "--engine", "ray", "--address", cluster.address, "--out", str(out),
                        "--no-progress"], cwd=REPO, env=cluster.env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "2 runs of ppo_cpg (rough x seeds 0-1) on the Ray cluster (2 nodes, 2 CPUs)" in " ".join(r.stderr.split())
    for seed in (0, 1):
        run = json.loads((out / f"ppo_cpg-rough-seed{seed}" / "run.json").read_text())
        assert run["seed"] == seed and run["env_steps"] >= 2048
        assert (out / f"ppo_cpg-rough-seed{seed}" / run["checkpoints"][-1]["file"]).is_file()
        assert (out / f"ppo_cpg-rough-seed{seed}" / "progress.csv").is_file()
    rows = (out / "ppo_cpg-runs.csv").read_text().splitlines()[1:]
    assert [row.split(",")[3] for row in rows] == ["done", "done"]


@needs_ray
def test_a_node_dying_mid_run_loses_no_episode(cluster, local_run, tmp_path):
    """Last in this module: the second node stays dead."""
    import psutil

    out = _with_secret_of(local_run, tmp_path / "ray-kill")
    proc = _ray_run(cluster, out)
    raylet = cluster.second_raylet()
    deadline = time.monotonic() + 240
    controllers = []
    while time.monotonic() < deadline and proc.poll() is None:  # wait until the second node plays an episode
        controllers = [p for p in raylet.children(recursive=True) if p.name() == "bwrap"]
        if controllers and list((out / ".journal").glob("*.json")):
            break
        time.sleep(0.2)
    journaled = len(list((out / ".journal").glob("*.json")))
    assert controllers and proc.poll() is None and journaled < 9, "the run ended before the node could be killed"
    workers = raylet.children()
    raylet.send_signal(signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    _same_record(local_run, out)
    # the dead node's Ray workers and their sandboxed controller processes are gone too
    gone, alive = psutil.wait_procs(workers + controllers, timeout=30)
    assert not alive, [p.pid for p in alive]


@needs_ray
def test_verify_replays_on_the_cluster_as_it_does_locally_and_catches_a_flipped_log(cluster, local_run, tmp_path):
    def verify_on_ray(run: Path) -> subprocess.CompletedProcess:
        return subprocess.run([str(BIN / "hexbench"), "verify", str(run), "--engine", "ray", "--address", cluster.address],
                              cwd=REPO, env={**cluster.env, "HEXBENCH_TASKS_DIR": os.environ["HEXBENCH_TASKS_DIR"]},
                              capture_output=True, text=True, timeout=300)

    ok = verify_on_ray(local_run)
    assert ok.returncode == 0, ok.stderr
    assert "all 9 episodes replay exactly from their action logs" in ok.stdout.replace("\n", " ")
    # one byte of one action log changed: the log no longer matches its row, on the cluster too
    forged = tmp_path / "forged"
    shutil.copytree(local_run, forged)
    log = sorted((forged / "episodes").glob("*.actions"))[0]
    data = bytearray(log.read_bytes())
    data[-1] ^= 0x01
    log.write_bytes(bytes(data))
    caught = verify_on_ray(forged)
    assert caught.returncode == 1 and log.name in caught.stderr, caught.stderr
    assert len([line for line in caught.stderr.splitlines() if line.startswith("error")]) == 1
    # a log that is a pipe: the cluster's line names it as the local one does, not as missing
    log.unlink()
    os.mkfifo(log)
    piped = verify_on_ray(forged)
    errors = [line for line in piped.stderr.splitlines() if line.startswith("error")]
    assert piped.returncode == 1 and len(errors) == 1 and "is a pipe" in errors[0] and log.name in errors[0], piped.stderr
