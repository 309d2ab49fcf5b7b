"""The command line's hand-offs: --version, `list --ids`, a partial run's AUC labelled as partial,
verify and Minari export of a run folder from any directory, and HexbenchErrors as one line."""

import shutil
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

import hexbench
from hexbench.cli import HexbenchGroup, app
from hexbench.commands.core import auc_text
from hexbench.commands.recording import find_controller
from hexbench.errors import HexbenchError
from hexbench.suite.tasks import registered_ids

REPO = Path(__file__).resolve().parent.parent
CPG = REPO / "baselines" / "cpg.py"

# Two paper levels on rough, so that a run of one of them is partial; short episodes.
TWO_LEVEL_PROTOCOL = """protocol = "v1"
episodes_per_level = 2
max_steps = 20
goal_distance_m = 2.5
max_lateral_deviation_m = 0.8
fall_tilt_deg = 60.0
stall_window_s = 20.0
stall_min_progress_m = 0.05

[terrains.rough]
unit = "cm"
levels = [3, 6]
headroom_levels = [9]

[terrains.stairs]
unit = "cm"
levels = [2]
headroom_levels = []
"""


@pytest.fixture(scope="module")
def protocol(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli_tasks")
    (folder / "protocol_v1.toml").write_text(TWO_LEVEL_PROTOCOL)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HEXBENCH_TASKS_DIR", str(folder))
        yield folder


@pytest.fixture(scope="module")
def partial_run(protocol, tmp_path_factory):
    """`hexbench run walker.py --terrain rough --level 3 --episodes 1 --out run`, started in the
    controller's folder: the run names its controller and was written relative to that folder."""
    start = tmp_path_factory.mktemp("started_here")
    shutil.copy(CPG, start / "walker.py")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(start)
        res = CliRunner().invoke(app, ["run", "walker.py", "--terrain", "rough", "--level", "3", "--episodes", "1",
                                       "--workers", "1", "--out", "run"])
    assert res.exit_code == 0, res.output
    return start / "run", res.output


def test_version_prints_the_version():
    res = CliRunner().invoke(app, ["--version"])
    assert res.exit_code == 0, res.output
    assert res.output.strip() == f"hexbench {hexbench.__version__}"


def test_list_ids_prints_the_gymnasium_ids_only():
    res = CliRunner().invoke(app, ["list", "--ids"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines() == [i for i in registered_ids() if i.endswith("-v1")]
    assert "hexbench/Flat-Joint-v1" in res.output.splitlines()


def test_plain_list_keeps_its_table():
    res = CliRunner().invoke(app, ["list"])
    assert res.exit_code == 0, res.output
    assert "paper levels (Table 4)" in res.output and "Gymnasium ids registered (--ids lists them)" in res.output


def test_list_of_an_unknown_protocol_is_one_line():
    res = CliRunner().invoke(app, ["list", "--ids", "--protocol", "v7"])
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == ["error: unknown protocol 'v7'; valid protocols: v1"]


def test_a_partial_run_labels_its_auc_as_partial(partial_run):
    _, output = partial_run
    assert "partial AUC" in output and "over 1 of 2 paper levels; not the terrain's AUC" in output
    assert "AUC over paper levels" not in output


def test_all_levels_with_fewer_episodes_says_so(protocol, tmp_path):
    res = CliRunner().invoke(app, ["run", str(CPG), "--terrain", "rough", "--episodes", "1", "--workers", "1",
                                   "--no-record", "--out", str(tmp_path / "run")])
    assert res.exit_code == 0, res.output
    assert "AUC over paper levels 0.000 (from 1 episode(s) per level; the protocol runs 2)" in res.output
    assert "partial AUC" not in res.output


def test_auc_text_without_any_paper_level(protocol):
    record = {"protocol": "v1", "levels": [{"terrain": "rough", "level": 9.0, "headroom": True, "episodes": 1}]}
    assert auc_text(record, {"terrain": "rough", "auc": None}) == "no AUC (none of the 2 paper levels run)"
    full = {"protocol": "v1", "levels": [{"terrain": "rough", "level": v, "headroom": False, "episodes": 2}
                                         for v in (3.0, 6.0)]}
    assert auc_text(full, {"terrain": "rough", "auc": 0.5}) == "AUC over paper levels 0.500"


def test_verify_works_from_any_directory(partial_run, tmp_path, monkeypatch):
    run, _ = partial_run
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, ["verify", str(run), "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert "all 1 episodes replay exactly" in res.output
    # the record names walker.py relative to the folder the run was started in; not found here
    assert "controller walker.py: not found in the current folder or the repository" in res.output
    episode = CliRunner().invoke(app, ["verify", str(run / "episodes" / "rough-3cm-00.mcap")])
    assert episode.exit_code == 0, episode.output
    assert "match the re-simulation from its action log exactly" in episode.output

    monkeypatch.chdir(run.parent)  # where the run was started: the controller is found and checked
    res = CliRunner().invoke(app, ["verify", str(run), "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert "is the file that made the episodes (sha256 matches)" in res.output


def test_a_controller_path_is_found_relative_to_the_repository(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert find_controller("baselines/cpg.py") == REPO / "baselines" / "cpg.py"
    assert find_controller("no/such/controller.py") is None


def test_verify_of_a_missing_path_is_one_line(tmp_path):
    res = CliRunner().invoke(app, ["verify", str(tmp_path / "nothing")])
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [f"error: {tmp_path / 'nothing'}: no such run folder or episode file"]


def test_export_minari_works_from_any_directory(partial_run, tmp_path, monkeypatch):
    minari = pytest.importorskip("minari")
    run, _ = partial_run
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, ["export", "minari", str(run)])
    assert res.exit_code == 0, res.output
    assert "wrote Minari dataset hexbench/run-rough-3cm-v0 (1 episodes, " in res.output
    assert f"load with: MINARI_DATASETS_PATH={run.resolve() / 'minari'} python -c" in res.output
    assert not (tmp_path / "minari").exists()
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(run / "minari"))
    assert minari.load_dataset("hexbench/run-rough-3cm-v0").total_episodes == 1

    again = CliRunner().invoke(app, ["export", "minari", str(run)])  # the dataset exists: one line, nothing changed
    assert again.exit_code == 2
    folder = run.resolve() / "minari"
    expected = (f"error: dataset hexbench/run-rough-3cm-v0 already exists in {folder}; remove "
                f"{folder / 'hexbench/run-rough-3cm-v0'} or choose another --dataset-id")
    assert [ln for ln in again.output.splitlines() if ln.strip()] == [expected]


def test_a_hexbench_error_from_any_command_is_one_line_and_exit_1():
    demo = typer.Typer(cls=HexbenchGroup)

    @demo.command("fail")
    def fail() -> None:
        raise HexbenchError("the input is broken\nsecond line")

    @demo.command("other")
    def other() -> None:
        pass

    res = CliRunner().invoke(demo, ["fail"])
    assert res.exit_code == 1
    assert res.output.splitlines() == ["error: the input is broken"]
