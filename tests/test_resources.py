"""Resets and env lifetimes do not leak memory or PyBullet physics clients."""

from __future__ import annotations

import gc

import gymnasium as gym
import numpy as np
import psutil
import pybullet as p

import hexbench  # noqa: F401
from hexbench.world.env import EnvConfig, HexapodEnv

MAX_GROWTH_MB = 50.0


def rss_mb() -> float:
    gc.collect()
    return psutil.Process().memory_info().rss / 2**20


def connected_clients(up_to: int) -> list[int]:
    return [cid for cid in range(up_to + 1) if p.isConnected(cid)]


def test_200_resets_do_not_grow_memory_or_leave_clients() -> None:
    """Rough terrain rebuilds a heightfield on every reset: the most memory per reset of all terrains.

    Every 10th reset is followed by 20 steps, so contact and solver caches are exercised too.
    """
    probe = p.connect(p.DIRECT)  # the next free client id tells which clients existed before
    p.disconnect(probe)
    before = connected_clients(probe + 50)
    env = HexapodEnv(EnvConfig(terrain="rough", level=12.0, action_mode="cpg_residual"))
    try:
        for k in range(10):  # warm-up: first-use allocations are not leaks
            env.reset(seed=k)
        baseline_mb = rss_mb()
        zeros = np.zeros(18, dtype=np.float32)
        for k in range(200):
            env.reset(seed=1000 + k)
            if k % 10 == 0:
                for _ in range(20):
                    env.step(zeros)
        growth_mb = rss_mb() - baseline_mb
        assert growth_mb < MAX_GROWTH_MB, f"200 resets grew memory by {growth_mb:.1f} MB"
        # one physics client for the env, however often it was reset
        assert len(connected_clients(probe + 50)) == len(before) + 1
    finally:
        env.close()
    assert connected_clients(probe + 50) == before


def test_closed_and_dropped_envs_leave_no_physics_clients() -> None:
    probe = p.connect(p.DIRECT)
    p.disconnect(probe)
    before = connected_clients(probe + 100)
    for k in range(20):
        env = gym.make("hexbench/Stairs-5cm-CpgResidual-v1")
        env.reset(seed=k)
        env.close()
        env.close()  # closing twice is harmless
    assert connected_clients(probe + 100) == before
    # an env that is never closed releases its client when it is garbage collected
    dropped = HexapodEnv(EnvConfig(terrain="flat"))
    dropped.reset(seed=0)
    client = dropped.sim.client
    assert p.isConnected(client)
    del dropped
    gc.collect()
    assert not p.isConnected(client)
    assert connected_clients(probe + 100) == before


def test_many_env_lifetimes_do_not_grow_memory() -> None:
    for k in range(5):  # warm-up
        HexapodEnv(EnvConfig(terrain="rough", level=5.0)).close()
    baseline_mb = rss_mb()
    for k in range(50):
        env = HexapodEnv(EnvConfig(terrain="rough", level=5.0))
        env.reset(seed=k)
        env.close()
    growth_mb = rss_mb() - baseline_mb
    assert growth_mb < MAX_GROWTH_MB / 2, f"50 env lifetimes grew memory by {growth_mb:.1f} MB"
