"""hexbench.agents.decision: a policy that decides every K control steps."""

import gymnasium as gym
import numpy as np
import pytest

from hexbench.agents.decision import DecisionInterval


def test_decision_interval_holds_the_action_sums_rewards_and_stops_at_the_episode_end() -> None:
    class Counting(gym.Env):
        observation_space = gym.spaces.Box(-1, 1, (1,))
        action_space = gym.spaces.Box(-1, 1, (1,))

        def __init__(self):
            self.actions, self.t = [], 0

        def reset(self, *, seed=None, options=None):
            self.t = 0
            return np.zeros(1, np.float32), {}

        def step(self, action):
            self.t += 1
            self.actions.append(float(action[0]))
            return np.full(1, self.t, np.float32), 1.0, self.t >= 5, False, {"t": self.t}

    env = DecisionInterval(Counting(), 3)
    env.reset()
    obs, reward, terminated, _, info = env.step(np.array([0.5]))
    assert (reward, terminated, info["decision_env_steps"], obs[0]) == (3.0, False, 3, 3.0)
    obs, reward, terminated, _, info = env.step(np.array([-0.5]))
    assert (reward, terminated, info["decision_env_steps"], info["t"]) == (2.0, True, 2, 5)  # ended after 2
    assert env.unwrapped.actions == [0.5, 0.5, 0.5, -0.5, -0.5]
    with pytest.raises(ValueError, match="decision interval must be >= 1"):
        DecisionInterval(Counting(), 0)
