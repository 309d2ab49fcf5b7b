"""A policy that decides every K control steps, as a Gymnasium wrapper (the config option
`decision_interval_steps`, not in the paper).

The policy's action is held for K control steps: one step of the wrapped env is K control steps
of the inner one (fewer if the episode ends first), with the summed reward, the last step's
observation and info, and `info["decision_env_steps"]` saying how many control steps the decision
took. Training (`hexbench.training.envs`) and the SB3 env of a shipped baseline
(`hexbench.agents.sb3.curriculum_env`) wrap with it; evaluation holds the action the same way in
`hexbench.agents.policy.PolicyController`. Why HRL needs it: a policy asked for CPG parameters
every 1/60 s learns to switch them bang-bang (the shipped HRL v4's hip amplitude A1 moves by 0.48
of its [-1, 1] range per control step on stairs 2 cm), which no longer makes the CPG's gait.
"""

from __future__ import annotations

import gymnasium as gym


class DecisionInterval(gym.Wrapper):
    """One step = the action held for `steps` control steps (fewer if the episode ends first)."""

    def __init__(self, env: gym.Env, steps: int):
        if steps < 1:
            raise ValueError(f"decision interval must be >= 1 control step (got {steps})")
        super().__init__(env)
        self.steps = int(steps)

    def step(self, action):
        total = 0.0
        for taken in range(1, self.steps + 1):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        info = dict(info)
        info["decision_env_steps"] = taken
        return obs, total, terminated, truncated, info
