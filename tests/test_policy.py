"""Trained-policy controllers: the waypoint a policy sees on a course longer than training's goal."""

import json
from pathlib import Path

import numpy as np
import pytest

from hexbench.agents.policy import (
    BASE_X_INDEX,
    OBS_SCALE,
    TARGET_X_INDEX,
    PolicyController,
    actor_layers,
    deterministic_action,
    load_policy,
    scale_observation,
    waypoint_horizon_m,
)
from hexbench.suite.controller import load_controller_module
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
SHIPPED = json.loads((REPO / "baselines" / "checkpoints" / "manifest.json").read_text())["checkpoints"]


class RecordingPolicy:
    def __init__(self):
        self.seen = []

    def predict(self, obs, deterministic=True):
        self.seen.append(np.array(obs))
        return np.zeros(18), None


def test_target_is_held_at_most_the_horizon_ahead_of_the_base():
    policy = RecordingPolicy()
    ctrl = PolicyController("cpg_residual", policy, target_horizon_m=2.5)
    obs = np.zeros(62, np.float32)
    obs[BASE_X_INDEX], obs[TARGET_X_INDEX] = 1.0, 6.3
    ctrl.act(obs)
    assert policy.seen[-1][TARGET_X_INDEX] == np.float32(3.5 * OBS_SCALE[TARGET_X_INDEX])
    assert obs[TARGET_X_INDEX] == np.float32(6.3)  # the caller's observation is untouched
    obs[BASE_X_INDEX] = 5.0  # within the horizon of the goal: the goal itself
    ctrl.act(obs)
    assert policy.seen[-1][TARGET_X_INDEX] == np.float32(6.3 * OBS_SCALE[TARGET_X_INDEX])


def test_without_a_horizon_the_observation_passes_unchanged():
    policy = RecordingPolicy()
    obs = np.arange(62, dtype=np.float32)
    PolicyController("cpg_residual", policy).act(obs)
    np.testing.assert_array_equal(policy.seen[-1], (obs * OBS_SCALE).astype(np.float32))


def test_waypoint_only_on_courses_longer_than_training():
    suite = load_suite()
    assert waypoint_horizon_m(suite.task("rough", 3.0).goal_distance_m) is None  # the 2.5 m goal itself
    mixed = [t for t in suite.extra_tasks if t.terrain == "mixed"][0]
    assert mixed.goal_distance_m > 2.5 and waypoint_horizon_m(mixed.goal_distance_m) == 2.5


@pytest.mark.parametrize("key", sorted(SHIPPED))
def test_the_fast_deterministic_action_is_bit_for_bit_sb3_predict_on_every_shipped_checkpoint(key):
    entry = SHIPPED[key]
    config = load_controller_module(REPO / "baselines" / f"{entry['method']}.py").CONFIG
    policy = load_policy(config, REPO / "baselines" / "checkpoints" / entry["file"], entry["sha256"])
    for obs in np.random.default_rng(0).normal(0.0, 2.0, size=(40, 62)).astype(np.float32):
        scaled = scale_observation(obs)
        expected, _ = policy.predict(scaled, deterministic=True)
        got = deterministic_action(policy, scaled)
        assert got.dtype == expected.dtype and np.array_equal(got, expected)
    assert actor_layers(policy) is not None  # the flat path was the one compared


def test_a_decision_interval_holds_each_decision_for_that_many_steps_and_resets_per_episode():
    policy = RecordingPolicy()
    ctrl = PolicyController("cpg_params", policy, decision_interval_steps=3)
    obs = np.zeros(62, np.float32)
    for _ in range(7):
        ctrl.act(obs)
    assert len(policy.seen) == 3  # decisions at steps 0, 3 and 6
    ctrl.reset(1)
    ctrl.act(obs)
    assert len(policy.seen) == 4  # a new episode starts with a new decision


@pytest.mark.parametrize("method", ["sac", "sac_cpg", "td3", "td3_cpg"])
def test_off_policy_critics_have_their_own_smaller_network_and_the_actor_keeps_table_2s(method):
    import torch

    from hexbench.agents.policy import build_policy

    config = load_controller_module(REPO / "baselines" / f"{method}.py").CONFIG
    policy = build_policy(config)

    def hidden_sizes(module) -> list[int]:  # every linear layer but the outputs (action: 18, Q: 1)
        return [m.out_features for m in module.modules() if isinstance(m, torch.nn.Linear) and m.out_features not in (1, 18)]

    assert hidden_sizes(policy.actor) == [256, 256, 256, 256]
    assert [hidden_sizes(q) for q in policy.critic.q_networks] == [[256, 256], [256, 256]]
    assert config.train_freq == 4 and config.gradient_steps == 1


def test_a_critic_network_is_refused_where_there_is_no_separate_critic():
    from dataclasses import replace

    from hexbench.agents.policy import ConfigError, validate_config

    ppo = load_controller_module(REPO / "baselines" / "ppo_cpg.py").CONFIG
    with pytest.raises(ConfigError, match="critic_net_arch is for algo 'sac' or 'td3'"):
        validate_config(_with_critic(ppo))
    sac = load_controller_module(REPO / "baselines" / "sac_cpg.py").CONFIG
    with pytest.raises(ConfigError, match="positive layer sizes"):
        validate_config(replace(sac, critic_net_arch=(256, 0)))


def _with_critic(config):
    """A copy of a config dataclass with a critic_net_arch field added."""
    from dataclasses import asdict, make_dataclass

    cls = make_dataclass("WithCritic", [(k, object) for k in asdict(config)] + [("critic_net_arch", object)], frozen=True)
    return cls(**asdict(config), critic_net_arch=(64,))


def test_with_a_heading_hold_the_policy_chooses_the_gait_and_the_hold_turns_at_every_step():
    from hexbench.agents.heading import BASE_YAW_INDEX, HeadingHold

    class GaitPolicy(RecordingPolicy):
        def predict(self, obs, deterministic=True):
            self.seen.append(np.array(obs))
            return np.array([0.1, 0.2, 0.3, 0.4]), None

    policy, hold = GaitPolicy(), HeadingHold()
    ctrl = PolicyController("cpg_params_steer", policy, decision_interval_steps=3, heading_hold=hold)
    for step in range(6):
        obs = np.zeros(62, np.float32)
        obs[BASE_YAW_INDEX] = 0.01 * step  # the heading drifts left: the hold turns right, more each step
        action = ctrl.act(obs)
        assert action.shape == (5,) and np.allclose(action[:4], [0.1, 0.2, 0.3, 0.4])
        assert action[4] == pytest.approx(hold.turn(obs) / 0.3)
    assert len(policy.seen) == 2  # the gait is decided every 3 steps, the turn at every step


def test_a_heading_hold_config_builds_a_gait_only_policy_and_needs_a_steering_mode():
    from dataclasses import replace

    from hexbench.agents.policy import ConfigError, build_policy, validate_config

    config = load_controller_module(REPO / "baselines" / "hrl_hold.py").CONFIG
    validate_config(config)
    assert build_policy(config).action_space.shape == (4,)  # the turn is the hold's
    with pytest.raises(ConfigError, match="heading_hold needs a steering action_mode"):
        validate_config(replace(config, action_mode="cpg_params_wide"))
    with pytest.raises(ConfigError, match="initial_action must be 4 numbers"):
        validate_config(replace(config, initial_action=(0.0,) * 5))
