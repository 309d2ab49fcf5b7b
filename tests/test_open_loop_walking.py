"""Done-criterion of the world: with a_r = 0 the paper's open-loop CPG walks to the 2.5 m goal on flat
ground and on the lowest level of every terrain (rough 3 cm, slopes 6 deg, stairs 2 cm)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import hexbench  # noqa: F401
from hexbench.suite.tasks import load_suite

SUITE = load_suite("v1")
LOWEST = [("flat", None), ("rough", 3.0), ("slopes", 6.0), ("stairs", 2.0)]


def gym_id(terrain: str, level: float | None) -> str:
    if terrain == "flat":
        return "hexbench/Flat-CpgResidual-v1"
    return SUITE.task(terrain, level).gym_id("cpg_residual")


def walk(env_id: str, seed: int) -> dict:
    env = gym.make(env_id)
    try:
        env.reset(seed=seed)
        zeros = np.zeros(env.action_space.shape, dtype=np.float32)
        max_abs_y = 0.0
        while True:
            _, _, terminated, truncated, info = env.step(zeros)
            max_abs_y = max(max_abs_y, abs(info["lateral_m"]))
            if terminated or truncated:
                return {**info, "max_abs_y": max_abs_y, "steps": env.unwrapped._steps}
    finally:
        env.close()


@pytest.mark.parametrize("terrain, level", LOWEST)
def test_open_loop_cpg_reaches_the_goal(terrain: str, level: float | None) -> None:
    seed = SUITE.task(terrain, level).seeds()[0] if level is not None else 0
    result = walk(gym_id(terrain, level), seed)
    assert result["end_reason"] == "success", result["end_reason"]
    assert result["progress_m"] >= 2.5
    assert result["max_abs_y"] <= 0.8
    # well inside the 4000-step limit: at least ~6 cm/s
    assert result["steps"] < 2500, result["steps"]


@pytest.mark.slow
@pytest.mark.parametrize("terrain, level", LOWEST[1:])
def test_open_loop_cpg_passes_every_protocol_seed_of_the_lowest_level(terrain: str, level: float) -> None:
    """All 20 protocol episodes (the seeds fix terrain, start perturbation and noise)."""
    failures = []
    for seed in SUITE.task(terrain, level).seeds():
        result = walk(gym_id(terrain, level), seed)
        if result["end_reason"] != "success":
            failures.append((seed, result["end_reason"], round(result["progress_m"], 2)))
    assert not failures, failures
