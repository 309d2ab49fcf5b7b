import os
import shutil
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def pytest_configure(config):
    """Under pytest-xdist (`make test` runs one test process per core) each test process and every
    run it starts get a temporary folder of their own: tests that look for what a run left in the
    temporary folder (sandbox folders, Ray worker folders, the screenshot) must not see another
    test process's runs."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if not worker:
        return
    own = Path(tempfile.gettempdir()) / f"hexbench-tests-{worker}-{os.getpid()}"
    own.mkdir(mode=0o700)
    os.environ["TMPDIR"] = str(own)
    tempfile.tempdir = None  # gettempdir() reads TMPDIR again
    config.add_cleanup(lambda: shutil.rmtree(own, ignore_errors=True))


@pytest.fixture
def repo() -> Path:
    return REPO


@pytest.fixture
def small_disk():
    """`mount(folder, size_bytes)`: the bubblewrap command prefix that runs a command with a
    `size_bytes` tmpfs on `folder` and everything else as it is (a disk that fills for real);
    skips the test where bubblewrap cannot mount one."""
    import subprocess

    def mount(folder: Path, size_bytes: int) -> list[str]:
        folder.mkdir(parents=True, exist_ok=True)
        prefix = ["bwrap", "--dev-bind", "/", "/", "--size", str(size_bytes), "--tmpfs", str(folder), "--"]
        if shutil.which("bwrap") is None or subprocess.run([*prefix, "true"], capture_output=True).returncode != 0:
            pytest.skip("bubblewrap cannot mount a tmpfs here")
        return prefix

    return mount


TINY_PROTOCOL = """# A one-level-per-terrain protocol for fast end-to-end tests (same rules as v1, short episodes).
protocol = "v1"
episodes_per_level = 2
max_steps = 40
goal_distance_m = 2.5
max_lateral_deviation_m = 0.8
fall_tilt_deg = 60.0
stall_window_s = 20.0
stall_min_progress_m = 0.05
action_noise = false

[terrains.rough]
unit = "cm"
levels = [3]
headroom_levels = []

[terrains.slopes]
unit = "deg"
levels = [6]
headroom_levels = []

[terrains.stairs]
unit = "cm"
levels = [2]
headroom_levels = []
"""


@pytest.fixture
def tiny_protocol(tmp_path_factory, monkeypatch):
    """HEXBENCH_TASKS_DIR pointed at a tiny protocol v1 (one level per terrain, 2 episodes of 40 steps),
    so a whole "full run" takes seconds (load_suite reads the folder in effect at each call)."""

    folder = tmp_path_factory.mktemp("tiny_tasks")
    (folder / "protocol_v1.toml").write_text(TINY_PROTOCOL)
    monkeypatch.setenv("HEXBENCH_TASKS_DIR", str(folder))
    yield folder
