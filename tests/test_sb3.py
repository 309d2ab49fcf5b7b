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
        controller.reset(0)  # a fresh decision on every observation (HRL-family controllers hold theirs)
        expected = controller.act(raw_obs)
        got, _ = model.predict(env.observation(raw_obs), deterministic=True)
        # with a heading hold the model chooses the gait, the heading law (in the env: HeadingTurn) the turn
        assert np.array_equal(np.asarray(got, np.float64), expected[:len(got)]), key
        assert len(expected) - len(got) == (1 if getattr(controller, "heading_hold", None) else 0), key
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


def _end_rewards(env) -> list[tuple[str, float]]:
    """(wrapper name, reward before delta) of every end term in the wrapper chain."""
    import gymnasium as gym

    out = []
    while isinstance(env, gym.Wrapper):
        if hasattr(env, "_end_reward"):
            out.append((type(env).__name__, env._end_reward))
        env = env.env
    return out


@pytest.mark.parametrize("method", ["hrl_steer", "hrl_hold"])
def test_the_sb3_env_of_a_decision_interval_recipe_steps_as_training_does(method):
    """One step of `curriculum_env` is one decision of `hexbench train`'s env for the same CONFIG:
    same observations, rewards and ends for the same seed and actions, the same end terms."""
    from hexbench.agents.sb3 import curriculum_env
    from hexbench.training.envs import make_training_env

    config = load_controller_module(REPO / "baselines" / f"{method}.py").CONFIG
    sb3_env = curriculum_env(config, "rough")
    train_env = make_training_env("rough", config.action_mode, None, early_end_penalty=config.early_end_penalty,
                                  decision_interval_steps=config.decision_interval_steps,
                                  arrival_bonus=config.arrival_bonus, heading_hold=getattr(config, "heading_hold", False),
                                  end_terms_per_decision=getattr(config, "end_terms_per_decision", False))
    assert sb3_env.action_space == train_env.action_space
    assert _end_rewards(sb3_env) == _end_rewards(train_env) != []
    obs_a, _ = sb3_env.reset(seed=3)
    obs_b, _ = train_env.reset(seed=3)
    assert np.array_equal(obs_a, obs_b)
    rng = np.random.default_rng(0)
    for _ in range(3):
        action = rng.uniform(-1.0, 1.0, sb3_env.action_space.shape).astype(np.float32)
        obs_a, reward_a, *ends_a, info_a = sb3_env.step(action)
        obs_b, reward_b, *ends_b, info_b = train_env.step(action)
        assert info_a["decision_env_steps"] == config.decision_interval_steps == info_b["decision_env_steps"]
        assert np.array_equal(obs_a, obs_b) and reward_a == reward_b and ends_a == ends_b
    sb3_env.close()
    train_env.close()
