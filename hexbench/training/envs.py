"""The environments a run trains on: one curriculum env per worker (paper section 4.1: level up after
20 arrivals, reward times (1 + delta), observation noise), monitored and observation-scaled, as one
SB3 VecEnv (SubprocVecEnv for W > 1, DummyVecEnv for W = 1), and the reward normaliser's state.

A config with `normalize_reward = True` trains on rewards divided by a running estimate of the
discounted return's standard deviation (SB3's VecNormalize, rewards only; observations keep the
fixed OBS_SCALE, so a checkpoint is still the network alone). Why: the Table 1 returns are in the
hundreds to thousands, and SB3 clips the *joint* gradient norm of policy and value loss at
`max_grad_norm` (0.5). Measured on the rough PPO-CPG run (checkpoint 180,502, one minibatch): the
value-loss gradient norm was 2,556 against the policy loss's 5.7, so clipping scaled the policy
gradient by 0.0002 and the policy barely learned (its std went 0.368 -> 0.345 in 830k steps). The
normaliser's statistics are stored with every checkpoint in run.json (plain numbers, no pickle)
and restored on resume. Episode rewards in progress.csv stay the raw Table 1 returns.
"""

from __future__ import annotations

from functools import partial

import gymnasium as gym
import numpy as np

from hexbench.agents.decision import DecisionInterval
from hexbench.agents.heading import HeadingTurn
from hexbench.agents.sb3 import ScaledObservation
from hexbench.training.wrappers import Curriculum, CurriculumWrapper, make_curriculum_env, with_end_terms
from hexbench.world.env import EnvConfig, HexapodEnv


class TrainingWrapper(ScaledObservation):
    """The fixed observation scaling every network trains on (ScaledObservation), and access to the curriculum state."""

    def _curriculum(self) -> CurriculumWrapper | None:
        env = self.env
        while isinstance(env, gym.Wrapper):
            if isinstance(env, CurriculumWrapper):
                return env
            env = env.env
        return None

    def curriculum_state(self) -> dict:
        """The curriculum's level and arrivals at it; at one fixed level, that level and 0."""
        curriculum = self._curriculum()
        if curriculum is None:
            return {"level": float(self.env.unwrapped.level), "successes": 0}
        return curriculum.curriculum_state()

    def set_curriculum_state(self, level: float, successes: int) -> None:
        curriculum = self._curriculum()
        if curriculum is not None:  # at one fixed level there is nothing to restore
            curriculum.set_curriculum_state(level, successes)


def make_training_env(terrain: str, action_mode: str, residual_scale: float | None,
                      fixed_level: float | None = None, early_end_penalty: bool = False,
                      curriculum: Curriculum | None = None, decision_interval_steps: int = 1,
                      arrival_bonus: bool = False, heading_hold: bool = False,
                      end_terms_per_decision: bool = False) -> gym.Env:
    """The curriculum env of paper 4.1 (or another curriculum, or with fixed_level that level alone),
    noise on, with the early-end penalty and the arrival bonus if asked, monitored (episode returns with
    those terms and lengths in control steps), with actions held for `decision_interval_steps` control steps;
    with `heading_hold` the turn of a steering mode is set by the heading law (HeadingTurn) every control step.
    With `end_terms_per_decision` the end terms bound a discount per decision, not per control step
    (hexbench.training.wrappers)."""
    from stable_baselines3.common.monitor import Monitor

    control_steps_per_discount = decision_interval_steps if end_terms_per_decision else 1
    if fixed_level is None:
        env = make_curriculum_env(terrain, action_mode, residual_scale=residual_scale,
                                  early_end_penalty=early_end_penalty, arrival_bonus=arrival_bonus,
                                  curriculum=curriculum, control_steps_per_discount=control_steps_per_discount)
    else:
        env = HexapodEnv(EnvConfig(terrain=terrain, level=fixed_level, action_mode=action_mode,
                                   residual_scale=residual_scale))
        env = with_end_terms(env, early_end_penalty, arrival_bonus, control_steps_per_discount)
    if heading_hold:
        env = HeadingTurn(env)
    env = Monitor(env)
    if decision_interval_steps != 1:
        env = DecisionInterval(env, decision_interval_steps)
    return TrainingWrapper(env)


def make_vec_env(terrain: str, action_mode: str, workers: int, residual_scale: float | None = None,
                 fixed_level: float | None = None, early_end_penalty: bool = False,
                 normalize_reward_gamma: float | None = None, curriculum: Curriculum | None = None,
                 decision_interval_steps: int = 1, arrival_bonus: bool = False, heading_hold: bool = False,
                 end_terms_per_decision: bool = False):
    """The workers' envs as one VecEnv; with normalize_reward_gamma, rewards are normalised (VecNormalize)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    factories = [partial(make_training_env, terrain, action_mode, residual_scale, fixed_level, early_end_penalty,
                         curriculum, decision_interval_steps, arrival_bonus, heading_hold, end_terms_per_decision)
                 for _ in range(workers)]
    venv = DummyVecEnv(factories) if workers == 1 else SubprocVecEnv(factories, start_method="fork")
    if normalize_reward_gamma is None:
        return venv
    return VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=normalize_reward_gamma)


def make_run_vec_env(settings, config):
    """The VecEnv of a run: its terrain, config (action mode, eps, end terms, reward normalisation) and options."""
    return make_vec_env(settings.terrain, config.action_mode, settings.workers, config.residual_scale,
                        settings.fixed_level, getattr(config, "early_end_penalty", False),
                        config.gamma if getattr(config, "normalize_reward", False) else None, settings.curriculum,
                        getattr(config, "decision_interval_steps", 1), getattr(config, "arrival_bonus", False),
                        getattr(config, "heading_hold", False), getattr(config, "end_terms_per_decision", False))


def reward_normalizer_state(venv) -> dict | None:
    """The running return statistics of a reward-normalising VecEnv (None for a plain one)."""
    from stable_baselines3.common.vec_env import VecNormalize

    if not isinstance(venv, VecNormalize):
        return None
    rms = venv.ret_rms
    return {"mean": float(np.asarray(rms.mean)), "var": float(np.asarray(rms.var)), "count": float(rms.count)}


def restore_reward_normalizer(venv, state: dict | None) -> None:
    """Put saved return statistics (reward_normalizer_state) back into a reward-normalising VecEnv."""
    from stable_baselines3.common.vec_env import VecNormalize

    if isinstance(venv, VecNormalize) and state:
        venv.ret_rms.mean = np.float64(state["mean"])
        venv.ret_rms.var = np.float64(state["var"])
        venv.ret_rms.count = float(state["count"])


def restore_curriculum(venv, curriculum: list[dict] | None) -> None:
    """Put every env's saved curriculum state (level, arrivals at it) back."""
    for i, cur in enumerate(curriculum or []):
        venv.env_method("set_curriculum_state", cur["level"], cur["successes"], indices=[i])
