"""The shipped baselines as Stable-Baselines3 models, for users of SB3 and rl-zoo3.

    from hexbench.agents.sb3 import load_sb3
    model, env = load_sb3("ppo_cpg", "rough")          # a PPO model with the shipped weights, and its env
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)  # the action the baseline's controller takes
    model.learn(10_000)                                 # fine-tuning works too

Shipped files hold the acting weights only (no pickled SB3 `data` entry: nothing in them is
executed on load), so `PPO.load(path)` cannot read them; `load_sb3` builds the model of the
baseline's CONFIG (algorithm, network, hyper-parameters) and loads the weights into it, after
checking their sha256 against the manifest. What is not in the file starts fresh: PPO's value head
and exploration std (the std from the CONFIG), SAC's and TD3's critics and target networks.

The networks see observations scaled by `hexbench.agents.policy.OBS_SCALE` (joint velocities / 5):
`ScaledObservation` is that scaling as a Gymnasium wrapper, for any hexbench env (rl-zoo3:
`env_wrapper: hexbench.agents.sb3.ScaledObservation`). The env `load_sb3` returns is the
terrain's training curriculum (`hexbench/<Terrain>-Curriculum-<Mode>-v1`) with the CONFIG's
residual scale, end terms, heading hold and decision interval, so wrapped: one step of it is one
step of `hexbench train`'s env for that CONFIG.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from hexbench.agents.decision import DecisionInterval
from hexbench.agents.heading import HeadingTurn
from hexbench.agents.policy import (
    ACTING_PREFIXES,
    EXPLORATION_KEYS,
    OBS_SCALE,
    algo_class,
    fit_weights,
    load_policy_weights,
    policy_kwargs,
    sb3_kwargs,
    scale_observation,
    shipped_checkpoint,
)
from hexbench.artifacts.provenance import REPO_ROOT
from hexbench.errors import HexbenchError
from hexbench.suite.tasks import curriculum_id, register_envs
from hexbench.world.env import OBS_HIGH

SHIPPED_DIR = REPO_ROOT / "baselines" / "checkpoints"


class ScaledObservation(gym.ObservationWrapper):
    """Observations times OBS_SCALE, as float32: what every shipped network was trained on."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.observation_space = gym.spaces.Box(-OBS_HIGH * OBS_SCALE, OBS_HIGH * OBS_SCALE, dtype=np.float32)

    def observation(self, observation):
        return scale_observation(observation)


def curriculum_env(config, terrain: str, protocol: str = "v1") -> gym.Env:
    """The terrain's registered training curriculum for the config's action mode, observation-scaled,
    stepped as `hexbench train` steps it: the config's residual scale and end terms (per decision
    with `end_terms_per_decision`), the heading law setting the turn every control step with
    `heading_hold`, and one step per decision with `decision_interval_steps`."""
    kwargs = {"residual_scale": config.residual_scale} if config.action_mode == "cpg_residual" else {}
    if getattr(config, "early_end_penalty", False):
        kwargs["early_end_penalty"] = True
    if getattr(config, "arrival_bonus", False):
        kwargs["arrival_bonus"] = True
    interval = getattr(config, "decision_interval_steps", 1)
    if getattr(config, "end_terms_per_decision", False):
        kwargs["control_steps_per_discount"] = interval
    register_envs(protocol)
    env = gym.make(curriculum_id(terrain, config.action_mode, protocol), **kwargs)
    if getattr(config, "heading_hold", False):  # the policy chooses the gait, the heading law the turn
        env = HeadingTurn(env)
    if interval != 1:
        env = DecisionInterval(env, interval)
    return ScaledObservation(env)


def load_sb3(method: str, terrain: str, env: gym.Env | None = None, *, checkpoints_dir: Path = SHIPPED_DIR,
             baseline_file: Path | None = None, device: str = "cpu"):
    """(SB3 model with the shipped weights of `method` on `terrain`, the env it is bound to).

    `env` defaults to `curriculum_env(config, terrain)`; pass another (observation-scaled) env of
    the same spaces to act or fine-tune elsewhere. CheckpointError / ConfigError for an unknown
    method or terrain, a missing file or a sha256 that does not match the manifest."""
    from hexbench.suite.controller import load_controller_module

    baseline_file = Path(baseline_file or REPO_ROOT / "baselines" / f"{method}.py")
    if not baseline_file.is_file():
        valid = sorted(p.stem for p in (REPO_ROOT / "baselines").glob("*.py") if not p.stem.startswith("_"))
        raise HexbenchError(f"no baseline file {baseline_file}; methods: {', '.join(valid)}")
    config = load_controller_module(baseline_file).CONFIG
    path, entry = shipped_checkpoint(Path(checkpoints_dir), method, terrain)
    env = env if env is not None else curriculum_env(config, terrain)
    extra = {"use_sde": True} if getattr(config, "use_sde", False) else {}
    model = algo_class(config.algo)("MlpPolicy", env, device=device, verbose=0, policy_kwargs=policy_kwargs(config),
                                    **sb3_kwargs(config), **extra)
    state = {k: v for k, v in load_policy_weights(path, entry["sha256"]).items() if k not in EXPLORATION_KEYS}
    fit_weights(model.policy, state, path,
                needed=lambda k: k.startswith(ACTING_PREFIXES[config.algo]) and k not in EXPLORATION_KEYS)
    if hasattr(model.policy, "actor_target"):  # TD3: the target actor starts as a copy of the loaded actor
        model.policy.actor_target.load_state_dict(model.policy.actor.state_dict())
    model.policy.set_training_mode(False)
    return model, env
