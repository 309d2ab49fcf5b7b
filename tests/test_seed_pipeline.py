"""`hexbench seed-run FILE --terrain T --seed S`: one command from scratch to an admitted seed-run
folder; refusals before any training, and nothing written under the seeds folder when a stage fails."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hexbench.cli import app

REPO = Path(__file__).resolve().parent.parent
TD3 = REPO / "baselines" / "td3.py"


def seed_run(tmp_path: Path, *args: str, file: Path = TD3):
    folders = ["--seeds-dir", tmp_path / "seeds", "--training-dir", tmp_path / "training",
               "--scoring-dir", tmp_path / "scoring"]
    return CliRunner().invoke(app, ["seed-run", str(file), *args, "--no-progress", *map(str, folders)],
                              catch_exceptions=False)


def written(tmp_path: Path) -> list[str]:
    return sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))


def test_an_existing_seed_run_folder_is_refused_before_training(tmp_path):
    (tmp_path / "seeds" / "td3-stairs-seed1").mkdir(parents=True)
    result = seed_run(tmp_path, "--terrain", "stairs", "--seed", "1")
    assert result.exit_code == 2
    assert "seeds/td3-stairs-seed1: exists; a seed run is made once" in result.output
    assert written(tmp_path) == ["seeds", "seeds/td3-stairs-seed1"]


@pytest.mark.parametrize(("args", "message"), [
    (("--terrain", "moon", "--seed", "1"), "unknown terrain 'moon'; valid terrains: rough, slopes, stairs"),
    (("--terrain", "rough", "--seed", "-1"), "--seed -1: a seed run's seed is >= 0"),
])
def test_bad_terrain_or_seed_is_one_line_and_no_files(tmp_path, args, message):
    result = seed_run(tmp_path, *args)
    assert result.exit_code == 2 and message in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert written(tmp_path) == []


def test_a_seeds_folder_that_cannot_be_written_is_refused_before_training(tmp_path):
    (tmp_path / "seeds").write_text("a file where the seeds folder should be")
    result = seed_run(tmp_path, "--terrain", "rough", "--seed", "1")
    assert result.exit_code == 2
    assert "seeds: cannot be written (a path component is a file, not a folder)" in result.output
    assert written(tmp_path) == ["seeds"]


def test_a_file_without_a_recipe_is_refused(tmp_path):
    no_recipe = tmp_path / "mine.py"
    no_recipe.write_text("def make_controller(task):\n    return None\n")
    result = seed_run(tmp_path, "--terrain", "rough", "--seed", "1", file=no_recipe)
    assert result.exit_code == 2 and "CONFIG" in result.output
    assert written(tmp_path) == ["mine.py"]


def test_a_run_in_the_training_folder_made_otherwise_is_refused(tmp_path):
    run_dir = tmp_path / "training" / "td3-rough-seed1"
    run_dir.mkdir(parents=True)
    (run_dir / "run.json").write_text(json.dumps({"method": "td3", "terrain": "rough", "seed": 1, "workers": 1,
                                                  "config": {"learning_rate": 0.5}, "env_steps": 1_000_000}))
    result = seed_run(tmp_path, "--terrain", "rough", "--seed", "1")
    assert result.exit_code == 2 and "training/td3-rough-seed1: holds a run with config=" in result.output
    assert not (tmp_path / "seeds").exists() and not (tmp_path / "scoring").exists()


def test_the_recorded_command_names_the_options_away_from_their_defaults():
    from hexbench.leaderboard.seed_pipeline import SeedRunPlan

    assert SeedRunPlan(Path("baselines/td3.py"), "rough", 1).command == \
        "hexbench seed-run baselines/td3.py --terrain rough --seed 1"
    plan = SeedRunPlan(Path("baselines/td3.py"), "stairs", 2, replay_sample=None, seeds_dir=Path("my seeds"),
                       budget_env_steps=1_000_000, show_progress=False)
    assert plan.command == "hexbench seed-run baselines/td3.py --terrain stairs --seed 2 --sample 0 --seeds-dir 'my seeds'"


@pytest.mark.slow
def test_one_command_makes_a_seed_run_folder_that_joins_the_seeds_page(tmp_path):
    """A tiny budget (no update yet: TD3 acts from its fresh actor), the rest as a 1M run: held-out
    selection, the terrain's 280 protocol episodes sandboxed, 5 replayed, the folder admitted."""
    from hexbench.leaderboard.seeds import load_seed_runs

    result = seed_run(tmp_path, "--terrain", "stairs", "--seed", "3", "--steps", "200", "--sample", "5")
    assert result.exit_code == 0, result.output
    folder = tmp_path / "seeds" / "td3-stairs-seed3"
    assert sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()) == [
        "checkpoints/manifest.json", "checkpoints/td3-stairs.zip", "result-stairs.json",
        "training/progress.csv", "training/run.json", "training/selection.json"]
    loaded = load_seed_runs(tmp_path / "seeds")
    assert loaded.errors == [] and [(r.method, r.terrain, r.seed) for r in loaded.runs] == [("td3", "stairs", 3)]
    entry = json.loads((folder / "checkpoints" / "manifest.json").read_text())["checkpoints"]["td3-stairs"]
    assert entry["command"].startswith(f"hexbench seed-run {TD3} --terrain stairs --seed 3 --steps 200 --sample 5 "
                                       f"--seeds-dir {tmp_path / 'seeds'}")
    assert json.loads((folder / "training" / "run.json").read_text())["command"] == entry["command"]
    record = json.loads((folder / "result-stairs.json").read_text())
    assert record["admission"]["episodes_replayed"] == 5 and record["episodes"][0]["terrain"] == "stairs"
    assert len(record["episodes"]) == 280
    with open(tmp_path / "seeds" / "td3-runs.csv", newline="") as f:
        (row,) = csv.DictReader(f)
    assert (row["terrain"], row["seed"], row["status"]) == ("stairs", "3", "done")
    again = seed_run(tmp_path, "--terrain", "stairs", "--seed", "3", "--steps", "200", "--sample", "5")
    assert again.exit_code == 2 and "exists; a seed run is made once" in again.output
