"""Shipped weights as Stable-Baselines3 models: `load_sb3` gives the model that acts exactly as the
baseline's controller, bound to the observation-scaled training env."""

import json
from pathlib import Path

import numpy as np
import pytest

from hexbench.agents.sb3 import ScaledObservation, load_sb3
from hexbench.artifacts.manifest import CheckpointError
from hexbench.errors import HexbenchError
from hexbench.suite.controller import load_controller_module
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
SHIPPED = json.loads((REPO / "baselines" / "checkpoints" / "manifest.json").read_text())["checkpoints"]


@pytest.mark.parametrize("key", sorted(SHIPPED))
def test_a_shipped_file_loaded_through_sb3_acts_as_the_baselines_controller(key):
    method, terrain = SHIPPED[key]["method"], SHIPPED[key]["terrain"]
    model, env = load_sb3(method, terrain)
    assert isinstance(env, ScaledObservation)
    assert env.unwrapped.spec.id == env.spec.id and "Curriculum" in env.spec.id
    task = load_suite().task(terrain, load_suite().levels(terrain)[0])
    controller = load_controller_module(REPO / "baselines" / f"{method}.py").make_controller(task)
    first, _ = env.env.reset(seed=0)  # the env's own observation, before the scaling wrapper
    rng = np.random.default_rng(1)
    for raw_obs in [first, *rng.normal(0.0, 2.0, size=(20, 62)).astype(np.float32)]:
        expected = controller.act(raw_obs)
        got, _ = model.predict(env.observation(raw_obs), deterministic=True)
        assert np.array_equal(np.asarray(got, np.float64), expected), key
    env.close()


def test_unknown_method_or_terrain_is_one_line():
    with pytest.raises(HexbenchError, match="no baseline file .*methods: .*ppo_cpg"):
        load_sb3("ppo_cpgg", "rough")
    with pytest.raises(CheckpointError):
        load_sb3("ppo_cpg", "ice")


def test_the_rl_zoo3_hyperparameters_are_the_ppo_cpg_config():
    """baselines/rl_zoo3/ppo_cpg.yml states baselines/ppo_cpg.py's CONFIG for each curriculum id."""
    import gymnasium as gym
    import yaml

    from hexbench.agents.policy import policy_kwargs

    config = load_controller_module(REPO / "baselines" / "ppo_cpg.py").CONFIG
    zoo = yaml.safe_load((REPO / "baselines" / "rl_zoo3" / "ppo_cpg.yml").read_text())
    assert set(zoo) == {f"hexbench/{t}-Curriculum-CpgResidual-v1" for t in ("Rough", "Slopes", "Stairs")}
    for env_id, entry in zoo.items():
        assert env_id in gym.registry
        for name in ("learning_rate", "batch_size", "n_steps", "n_epochs", "gamma", "gae_lambda", "clip_range",
                     "ent_coef"):
            assert entry[name] == getattr(config, name), (env_id, name)
        assert entry["n_timesteps"] == 1e6 and entry["env_wrapper"] == "hexbench.agents.sb3.ScaledObservation"
        import torch.nn as nn

        assert eval(entry["policy_kwargs"], {"nn": nn}) == policy_kwargs(config)  # noqa: S307 - our own file
        assert eval(entry["normalize"]) == {"norm_obs": False, "norm_reward": config.normalize_reward,  # noqa: S307
                                            "gamma": config.gamma}
    assert not config.use_sde  # the zoo file states the paper's Gaussian exploration
