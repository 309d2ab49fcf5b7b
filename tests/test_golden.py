"""Committed leaderboard records are golden trajectories: episodes played now reproduce their rows exactly.

The physics is deterministic, so an episode of the open-loop CPG and of the shipped PPO-CPG, played
by today's code through the sandbox, must give the row the committed record holds, field for field.
A refactor that changes any outcome fails here, and so does a machine whose CPU makes the policy
multiply differently (the records were made on AMD EPYC machines; hexbench/suite/numerics.py).
"""

import json
from pathlib import Path

import pytest

from hexbench.artifacts.records import ROW_FIELDS
from hexbench.evaluation import sandbox
from hexbench.evaluation.episode import EpisodeJob, run_episode
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
CASES = [("cpg", "stairs", 2.0), ("ppo_cpg", "rough", 3.0), ("ppo_cpg", "stairs", 2.0)]


@pytest.fixture(autouse=True)
def _stop_controllers():
    yield
    sandbox.close_all()


@pytest.mark.parametrize("method, terrain, level", CASES)
def test_an_episode_played_now_reproduces_its_committed_row(method, terrain, level):
    record = json.loads((REPO / "leaderboard" / f"{method}.json").read_text())
    committed = next(r for r in record["episodes"] if r["terrain"] == terrain and r["level"] == level and r["index"] == 0)
    task = load_suite(record["protocol"]).task(terrain, level)
    job = EpisodeJob(str(REPO / "baselines" / f"{method}.py"), task, 0, committed["seed"],
                     isolation=sandbox.resolve_isolation("auto"))
    row = run_episode(job)
    assert {k: row[k] for k in ROW_FIELDS} == {k: committed[k] for k in ROW_FIELDS}
