"""`hexbench train FILE --terrain T,... --seeds S`: a batch of training runs in their usual folders,
resumable, one failed run failing alone; the files of a run that trained where the driver's files
are not come back. (The same batch on a two-node Ray cluster: tests/test_ray_engine.py.)"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hexbench.cli import app
from hexbench.training.batch import (
    TOKEN_FILE,
    BatchError,
    TrainBatch,
    land_run_files,
    parse_seeds,
    parse_terrains,
    single_run_command,
    train_task,
)
from hexbench.training.settings import TrainSettings

REPO = Path(__file__).resolve().parent.parent
PPO_CPG = REPO / "baselines" / "ppo_cpg.py"
TINY_PPO = ["--set", "n_steps=64", "--set", "batch_size=32", "--set", "n_epochs=1"]


def batch_cli(out: Path, *extra: str):
    """`hexbench train ...` as typed: the batch writes each run's own command from sys.argv, so the
    command line is set as the console script would see it (not the test runner's)."""
    args = ["train", str(PPO_CPG), "--steps", "64", *TINY_PPO, "--out", str(out), "--no-progress", "--parallel", "1",
            *extra]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "argv", ["hexbench", *args])
        return CliRunner().invoke(app, args)


def test_seed_and_terrain_lists_parse_and_bad_ones_are_one_line():
    assert parse_seeds("0-4") == (0, 1, 2, 3, 4)
    assert parse_seeds("3,0-1,3") == (0, 1, 3)
    assert parse_terrains("rough, slopes,rough") == ("rough", "slopes")
    for bad in ("", "a-b", "4-2", "-1", "1,,x"):
        with pytest.raises(BatchError, match="--seeds"):
            parse_seeds(bad)
    with pytest.raises(BatchError, match="unknown terrain 'ice'; valid terrains: rough, slopes, stairs"):
        parse_terrains("rough,ice")


def test_each_run_records_the_single_run_command_that_continues_it():
    argv = ["train", "baselines/ppo_cpg.py", "--terrain", "rough,stairs", "--seeds=0-4", "--steps", "1000000",
            "--engine", "ray", "--address", "10.0.0.1:6379", "--parallel", "3", "--set", "n_epochs=5", "--out", "t"]
    assert single_run_command(argv, "stairs", 3, Path("t/ppo_cpg-stairs-seed3")) == (
        "hexbench train baselines/ppo_cpg.py --steps 1000000 --set n_epochs=5 "
        "--terrain stairs --seed 3 --out t/ppo_cpg-stairs-seed3")


def test_a_batch_trains_every_terrain_and_seed_in_its_usual_folder_and_resumes(tmp_path):
    out = tmp_path / "training"
    r = batch_cli(out, "--terrain", "rough,stairs", "--seeds", "0-1")
    assert r.exit_code == 0, r.output
    rows = (out / "ppo_cpg-runs.csv").read_text().splitlines()
    assert rows[0].startswith("terrain,seed,run_dir,status,env_steps,total_steps")
    assert [tuple(row.split(",")[:2]) + (row.split(",")[3],) for row in rows[1:]] == [
        ("rough", "0", "done"), ("rough", "1", "done"), ("stairs", "0", "done"), ("stairs", "1", "done")]
    runs = {}
    for terrain in ("rough", "stairs"):
        for seed in (0, 1):
            run = json.loads((out / f"ppo_cpg-{terrain}-seed{seed}" / "run.json").read_text())
            assert (run["terrain"], run["seed"], run["env_steps"]) == (terrain, seed, 64)
            assert f"--terrain {terrain} --seed {seed} --out {out}/ppo_cpg-{terrain}-seed{seed}" in run["command"]
            assert "--seeds" not in run["command"] and "--parallel" not in run["command"]
            runs[(terrain, seed)] = run
    assert not (out / TOKEN_FILE).exists()
    # the same command again: nothing to train, every run left as it was
    assert batch_cli(out, "--terrain", "rough,stairs", "--seeds", "0-1").exit_code == 0
    for (terrain, seed), run in runs.items():
        assert json.loads((out / f"ppo_cpg-{terrain}-seed{seed}" / "run.json").read_text()) == run
    # a larger budget resumes every run from its last checkpoint
    r = CliRunner().invoke(app, ["train", str(PPO_CPG), "--steps", "128", *TINY_PPO, "--out", str(out),
                                 "--no-progress", "--terrain", "rough", "--seeds", "1"])
    assert r.exit_code == 0, r.output
    run = json.loads((out / "ppo_cpg-rough-seed1" / "run.json").read_text())
    assert [c["env_steps"] for c in run["checkpoints"]] == [64, 128] and run["sessions"][-1]["from_env_steps"] == 64


def test_a_failed_run_fails_alone_with_its_line(tmp_path):
    out = tmp_path / "training"
    other = out / "ppo_cpg-rough-seed1"
    other.mkdir(parents=True)
    (other / "run.json").write_text("{not json")  # a broken folder: this run cannot train, the other can
    r = batch_cli(out, "--terrain", "rough", "--seeds", "0,1")
    assert r.exit_code == 1
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error")]
    assert len(lines) == 1 and "1 of 2 runs failed (rough seed 1: " in lines[0] and "not valid JSON" in lines[0], lines
    assert json.loads((out / "ppo_cpg-rough-seed0" / "run.json").read_text())["env_steps"] == 64
    status = {row.split(",")[1]: row.split(",")[3] for row in (out / "ppo_cpg-runs.csv").read_text().splitlines()[1:]}
    assert status == {"0": "done", "1": "failed"}


@pytest.mark.parametrize("extra, message", [
    (["--terrain", "rough,ice", "--seeds", "0-1"], "unknown terrain 'ice'; valid terrains: rough, slopes, stairs"),
    (["--terrain", "rough", "--seeds", "x"], "--seeds 'x' is not a list of seeds"),
    (["--terrain", "rough", "--seeds", "0", "--engine", "spark"], "unknown engine 'spark'; valid: local, ray"),
    (["--terrain", "rough", "--engine", "ray"], "are for a batch of runs: add --seeds"),
    (["--terrain", "rough,slopes"], "are for a batch of runs: add --seeds"),
    (["--terrain", "rough", "--seeds", "0", "--set", "nope=1"], "config has no field 'nope'"),
])
def test_bad_batch_input_is_one_line_and_writes_nothing(tmp_path, extra, message):
    out = tmp_path / "training"
    r = batch_cli(out, *extra)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], lines
    assert not out.exists()


def test_a_run_trained_where_the_driver_files_are_not_ships_its_folder_back(tmp_path, monkeypatch):
    """As on a cluster node without a shared filesystem: the token the driver left in OUT is not there."""
    monkeypatch.chdir(REPO)
    out = tmp_path / "training"
    template = TrainSettings(baseline_path=PPO_CPG, terrain="", total_steps=64,
                             overrides=(("n_steps", 64), ("batch_size", 32), ("n_epochs", 1)))
    (settings,) = TrainBatch(template, ("rough",), (0,), out_root=out).runs()
    result = train_task((settings, str(REPO), str(out), "the driver's token, which this node cannot read"))
    assert result["error"] is None
    shipped = result["files"]
    assert {"run.json", "progress.csv", "checkpoints/step_0000000064.zip"} <= set(shipped)
    elsewhere = tmp_path / "driver" / "ppo_cpg-rough-seed0"
    land_run_files({**result, "run_dir": str(elsewhere)})
    assert {p.relative_to(elsewhere).as_posix(): p.read_bytes() for p in elsewhere.rglob("*") if p.is_file()} == shipped
    with pytest.raises(BatchError, match="a run shipped back a file outside its folder"):
        land_run_files({"run_dir": str(elsewhere), "files": {"../../escape": b"x"}})
    assert not (tmp_path / "escape").exists()
    # a node that shares the driver's files reads its token there, and ships nothing back
    (out / TOKEN_FILE).write_text("t0")
    assert train_task((settings, str(REPO), str(out), "t0"))["files"] is None
