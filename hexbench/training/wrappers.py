"""What training changes about the hexbench env, as Gymnasium wrappers around the plain `HexapodEnv`:

  CurriculumWrapper   the training curricula of paper 4.1 (CURRICULA): every episode plays at the
                      curriculum's current level; level up after `successes_per_level` arrivals,
                      up to the top level. The level changes on the step of the arrival that earns
                      it (`info["level"]`) and the next episode plays at the new level.
  EarlyEndPenalty     the training reward option `early_end_penalty` (not in the paper). r_d is
                      negative while d > 1 m, so with Table 1 as written an agent that ends its
                      episode early (a fall costs only 0.1 x 100 = 10, leaving the 0.8 m corridor
                      costs nothing) escapes a long run of negative rewards: PPO and PPO-CPG
                      trained without the penalty learned to drift out of the corridor. The penalty charges
                      every early end other than success with (1 + delta) w_d / (1 - gamma): since
                      r_d > -1, that bounds the discounted loss of staying alive, so ending the
                      episode never pays.
  ArrivalBonus        the training reward option `arrival_bonus` (not in the paper), the mirror
                      of the penalty: r_d grows to 9 as d falls to 0.1 m, and an arrival ends the
                      episode, so an agent that can steer (HRL-steer) learned to circle just short
                      of the goal line and collect r_d rather than arrive. The bonus pays every
                      arrival (1 + delta) (w_d (1/0.1 m - 1) + w_theta + w_r) / (1 - gamma): the
                      most r_d, r_theta and r_r can pay per step, discounted forever, so staying
                      never pays more than arriving (r_h, stairs only at weight 0.01 per cm above
                      12 cm, is left out).
  Both bounds assume the agent discounts by gamma per control step. A policy that decides every K
  control steps (DecisionInterval) is discounted per decision and is paid the sum of K control
  steps' rewards per decision, so staying near the goal is worth up to K times more than the bonus
  pays: HRL-hold (K = 30) learned to stop 0.1-0.5 m short of the goal while its training return
  kept rising. With the config option `end_terms_per_decision` both terms are K times larger, the
  bound for a discount per decision.

  DecisionInterval    the config option `decision_interval_steps` (not in the paper): the policy
                      decides every K control steps: hexbench.agents.decision, since the SB3 env of a
                      shipped baseline (hexbench.agents.sb3) wraps with it too.

`make_curriculum_env` is the entry point of the registered ids hexbench/<Terrain>-Curriculum-<Mode>-v1
(hexbench.suite.tasks registers them by entry-point string).
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym

from hexbench.world.env import HexapodEnv
from hexbench.world.rewards import MIN_DISTANCE_M, TABLE1_WEIGHTS, RewardWeights, difficulty_factor

EARLY_END_GAMMA = 0.99  # the discount the early-end penalty bounds the loss of staying alive with


@dataclass(frozen=True)
class Curriculum:
    """Training curriculum (paper 4.1): level up after `successes_per_level` arrivals; levels in the
    paper's units (cm for rough and stairs, deg for slopes)."""

    start_level: float
    level_step: float
    max_level: float
    successes_per_level: int = 20


CURRICULA: dict[str, Curriculum] = {
    "rough": Curriculum(5.0, 1.0, 13.0),
    "slopes": Curriculum(5.0, 3.0, 18.0),  # 5, 8, 11, 14, 17 (the paper caps at 18)
    "stairs": Curriculum(5.0, 0.5, 8.0),
}


def early_end_penalty(weights: RewardWeights, gamma: float = EARLY_END_GAMMA, control_steps_per_discount: int = 1) -> float:
    """The (negative) reward, before the (1 + delta) factor, for an early end other than success, for an
    agent that discounts by `gamma` once every `control_steps_per_discount` control steps."""
    return -control_steps_per_discount * weights.distance / (1.0 - gamma)


def arrival_bonus(weights: RewardWeights, gamma: float = EARLY_END_GAMMA, control_steps_per_discount: int = 1) -> float:
    """The reward, before the (1 + delta) factor, added on arrival (an end by success), for an agent
    that discounts by `gamma` once every `control_steps_per_discount` control steps."""
    most_per_step = weights.distance * (1.0 / MIN_DISTANCE_M - 1.0) + weights.heading + weights.tilt
    return control_steps_per_discount * most_per_step / (1.0 - gamma)


class CurriculumWrapper(gym.Wrapper):
    """Plays every episode at the curriculum's current level (reset option `level`); levels up."""

    def __init__(self, env: gym.Env, curriculum: Curriculum):
        super().__init__(env)
        self.curriculum = curriculum
        self.level = curriculum.start_level
        self.successes = 0  # arrivals at the current level

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        return self.env.reset(seed=seed, options={**(options or {}), "level": self.level})

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if info["end_reason"] == "success":
            self._count_success()
            info["level"] = self.level
        return obs, reward, terminated, truncated, info

    def _count_success(self) -> None:
        cur = self.curriculum
        self.successes += 1
        if self.successes >= cur.successes_per_level and self.level + cur.level_step <= cur.max_level + 1e-9:
            self.level = round(self.level + cur.level_step, 6)
            self.successes = 0

    def curriculum_state(self) -> dict:
        return {"level": float(self.level), "successes": int(self.successes)}

    def set_curriculum_state(self, level: float, successes: int) -> None:
        self.level = float(level)
        self.successes = int(successes)


class _EndReward(gym.Wrapper):
    """Adds (1 + delta) times a fixed reward [before delta] on the step an episode ends, for the ends
    `pays(end_reason)` picks; the reward comes from the terrain's Table 1 weights, the agent's
    discount and how many control steps it discounts once over."""

    def __init__(self, env: gym.Env, reward_of_weights, gamma: float = EARLY_END_GAMMA,
                 control_steps_per_discount: int = 1):
        super().__init__(env)
        self._terrain = env.unwrapped.config.terrain
        self._end_reward = reward_of_weights(TABLE1_WEIGHTS[self._terrain], gamma, control_steps_per_discount)
        self._delta = 0.0

    @staticmethod
    def pays(end_reason: str) -> bool:
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._delta = difficulty_factor(self._terrain, info["level"])
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated and self.pays(info["end_reason"]):
            reward += (1.0 + self._delta) * self._end_reward
        return obs, reward, terminated, truncated, info


class EarlyEndPenalty(_EndReward):
    """Adds (1 + delta) early_end_penalty(Table 1 weights) to the reward of an early end other than success."""

    def __init__(self, env: gym.Env, gamma: float = EARLY_END_GAMMA, control_steps_per_discount: int = 1):
        super().__init__(env, early_end_penalty, gamma, control_steps_per_discount)

    @staticmethod
    def pays(end_reason: str) -> bool:
        return end_reason != "success"


class ArrivalBonus(_EndReward):
    """Adds (1 + delta) arrival_bonus(Table 1 weights) to the reward of an arrival."""

    def __init__(self, env: gym.Env, gamma: float = EARLY_END_GAMMA, control_steps_per_discount: int = 1):
        super().__init__(env, arrival_bonus, gamma, control_steps_per_discount)

    @staticmethod
    def pays(end_reason: str) -> bool:
        return end_reason == "success"


def with_end_terms(env: gym.Env, early_end_penalty: bool, arrival_bonus: bool,
                   control_steps_per_discount: int = 1) -> gym.Env:
    """`env` with the training reward options that price an episode's end, for an agent that
    discounts once every `control_steps_per_discount` control steps."""
    if early_end_penalty:
        env = EarlyEndPenalty(env, control_steps_per_discount=control_steps_per_discount)
    return ArrivalBonus(env, control_steps_per_discount=control_steps_per_discount) if arrival_bonus else env


def make_curriculum_env(terrain: str, action_mode: str = "cpg_residual", *, residual_scale: float | None = None,
                        early_end_penalty: bool = False, arrival_bonus: bool = False,
                        curriculum: Curriculum | dict | None = None, control_steps_per_discount: int = 1,
                        **env_fields) -> gym.Env:
    """The training environment of paper 4.1 for a terrain: its curriculum (or `curriculum`, a
    Curriculum or its fields as a dict), observation noise on, no stall rule; with
    `early_end_penalty` and `arrival_bonus`, those too (for an agent that discounts once every
    `control_steps_per_discount` control steps). `env_fields` are further EnvConfig fields
    (hexbench.world.env)."""
    if isinstance(curriculum, dict):
        curriculum = Curriculum(**curriculum)
    if curriculum is None and terrain not in CURRICULA:
        raise ValueError(f"no training curriculum for terrain {terrain!r}; terrains with one: {', '.join(CURRICULA)}")
    env = HexapodEnv(terrain=terrain, action_mode=action_mode, residual_scale=residual_scale, **env_fields)
    env = CurriculumWrapper(env, curriculum or CURRICULA[terrain])
    return with_end_terms(env, early_end_penalty, arrival_bonus, control_steps_per_discount)


