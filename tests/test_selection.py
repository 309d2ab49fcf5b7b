"""Checkpoint selection on held-out episodes (`hexbench checkpoints select` and `publish --checkpoint heldout`)."""

from __future__ import annotations

import json

from hexbench.suite.tasks import load_suite
from hexbench.training.selection import SELECTION_LEVELS, heldout_seeds
from tests.test_train import run_cli, train_tiny


def test_heldout_seeds_are_fixed_and_never_protocol_seeds():
    suite = load_suite()
    for terrain, levels in SELECTION_LEVELS.items():
        for level in levels:
            task = suite.task(terrain, level)  # selection levels are protocol levels
            held = heldout_seeds(terrain, level, 20)
            assert held == heldout_seeds(terrain, level, 20)
            assert len(set(held)) == 20 and not set(held) & set(task.seeds())


def test_select_scores_new_checkpoints_then_publish_ships_the_best(tmp_path):
    out, dest = tmp_path / "run", tmp_path / "checkpoints"
    assert train_tiny("ppo_cpg", out, steps=64, terrain="stairs").exit_code == 0
    result = run_cli("checkpoints", "select", out, "--episodes", "1", "--level", "2")
    assert result.exit_code == 0, result.output
    table = json.loads((out / "selection.json").read_text())
    (first_sha, first), = table["checkpoints"].items()
    assert table["levels"] == [2.0] and table["namespace"] == "heldout"
    assert first["env_steps"] == 64 and first["episodes"][0]["seed"] == heldout_seeds("stairs", 2.0, 1)[0]

    # A resumed run adds a checkpoint; selecting again scores only that one and keeps the first result.
    assert train_tiny("ppo_cpg", out, steps=128, terrain="stairs").exit_code == 0
    assert run_cli("checkpoints", "select", out, "--episodes", "1", "--level", "2").exit_code == 0
    table = json.loads((out / "selection.json").read_text())
    assert sorted(c["env_steps"] for c in table["checkpoints"].values()) == [64, 128]
    assert table["checkpoints"][first_sha] == first

    # More episodes for the front-runner only: its first episode is kept, one more is played.
    assert run_cli("checkpoints", "select", out, "--episodes", "2", "--level", "2", "--top", "1").exit_code == 0
    table = json.loads((out / "selection.json").read_text())
    counts = sorted(len(c["episodes"]) for c in table["checkpoints"].values())
    assert counts == [1, 2]
    topped = next(c for c in table["checkpoints"].values() if len(c["episodes"]) == 2)
    assert sorted(e["seed"] for e in topped["episodes"]) == sorted(heldout_seeds("stairs", 2.0, 2))

    # A window of env steps: only the checkpoint at 128 steps gets its third episode.
    assert run_cli("checkpoints", "select", out, "--episodes", "3", "--level", "2", "--min-env-steps", "100").exit_code == 0
    table = json.loads((out / "selection.json").read_text())
    (early, early_n), late = sorted((c["env_steps"], len(c["episodes"])) for c in table["checkpoints"].values())
    assert late == (128, 3) and early == 64 and early_n < 3

    result = run_cli("checkpoints", "publish", out, "--checkpoint", "heldout", "--dest", dest)
    assert result.exit_code == 0, result.output
    entry = json.loads((dest / "manifest.json").read_text())["checkpoints"]["ppo_cpg-stairs"]
    assert entry["source_checkpoint_sha256"] == table["best"]["sha256"]
    assert entry["selection"]["levels"] == [2.0] and entry["selection"]["checkpoints_scored"] == 2
    assert entry["selection"]["rank"] == 1
    assert entry["selection"]["episodes"] == len(table["checkpoints"][table["best"]["sha256"]]["episodes"])


def test_select_bad_level_and_publish_without_selection_give_one_line(tmp_path):
    out = tmp_path / "run"
    assert train_tiny("ppo_cpg", out, steps=64, terrain="stairs").exit_code == 0
    result = run_cli("checkpoints", "select", out, "--level", "2.2")
    assert result.exit_code == 2
    assert "unknown stairs level 2.2; valid levels: 2, 3, 4" in result.output
    assert not (out / "selection.json").exists()
    result = run_cli("checkpoints", "publish", out, "--checkpoint", "heldout", "--dest", tmp_path / "dest")
    assert result.exit_code == 2 and "run `hexbench checkpoints select" in result.output
    assert not (tmp_path / "dest").exists()
    result = run_cli("checkpoints", "select", tmp_path / "nowhere")
    assert result.exit_code == 2 and "no run.json" in result.output
    result = run_cli("checkpoints", "select", out, "--level", "2", "--min-env-steps", "65")
    assert result.exit_code == 2 and "no checkpoint at >= 65 env steps (checkpoints run from 64 to 64)" in result.output
    # a run copied from another machine with only its last checkpoint: the error says which ones exist
    assert train_tiny("ppo_cpg", out, steps=128, terrain="stairs").exit_code == 0
    (out / "checkpoints" / "step_0000000064.zip").unlink()
    result = run_cli("checkpoints", "select", out, "--level", "2")
    assert result.exit_code == 2
    assert "1 chosen checkpoint(s) have no file (first: checkpoints/step_0000000064.zip); " \
           "files exist for 128 to 128 env steps" in result.output
    assert not (out / "selection.json").exists()
