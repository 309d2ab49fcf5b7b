"""Trained baseline policies: baseline configs, observation scaling, verified checkpoints, controllers.

A baseline file (baselines/*.py) defines a frozen config dataclass at its top and `CONFIG = Config()`.
Every config has these fields, read here and by hexbench.training (settings, envs, warm_start):

    algo           "ppo", "sac" or "td3" (the Stable-Baselines3 class)
    action_mode    "joint", "cpg_residual", "cpg_params", "cpg_params_wide" or "cpg_params_steer" (hexbench.world.env)
    net_arch       hidden layer sizes, e.g. (256, 256, 256, 256) (the policy; the critic too unless below)
    critic_net_arch (optional; SAC, TD3) the critics' hidden layer sizes when they differ from net_arch
    activation     "relu" or "tanh"
    residual_scale eps of eq. 6 (None: the terrain default of paper 3.2)
    log_std_init   (optional; PPO and SAC) initial log std of the Gaussian policy
    action_noise_std (optional; TD3, SAC) std of Gaussian exploration noise added to actions
    initial_action (optional; PPO) the policy's mean action before training (hexbench.training.warm_start)
    decision_interval_steps (optional, default 1) the policy decides every K control steps and its
                   action is held between, in training and in evaluation (hexbench.training.wrappers)
    early_end_penalty, arrival_bonus (optional, default False) training reward terms for how an
                   episode ends (hexbench.training.wrappers)
    end_terms_per_decision (optional, default False) those terms sized for a discount per decision
                   of decision_interval_steps control steps (hexbench.training.wrappers)
    heading_hold   (optional, default False; steering action modes) the turn is not learned: a fixed
                   heading law (hexbench.agents.heading.HeadingHold) sets it every control step, in
                   training and in evaluation, and the policy chooses the four gait values alone

and every other field is passed unchanged to the SB3 constructor (learning_rate, gamma, ...).

Checkpoints. Nothing is unpickled from a file whose sha256 was not checked first:
  * shipped weights (baselines/checkpoints/<method>-<terrain>.zip) hold only the policy's
    state_dict, and of SAC's and TD3's only the actor (ACTING_PREFIXES: the critics serve learning);
    `baselines/checkpoints/manifest.json` records each file's sha256. Loading reads
    the manifest, hashes the file, and only then opens the zip with SB3's `load_from_zip_file(...,
    load_data=False)`, which reads tensors with `torch.load(weights_only=True)` and skips the
    cloudpickled "data" entry altogether. The network is rebuilt from the baseline's config.
  * training checkpoints (full SB3 models, for resuming) are verified against the run's own
    run.json before `ALGO.load` (see hexbench.training.envs).
"""

from __future__ import annotations

import weakref
from dataclasses import asdict, fields, is_dataclass
from pathlib import Path

import numpy as np

from hexbench.agents.heading import HeadingHold, with_held_heading
from hexbench.artifacts.files import atomic_path, sha256_file
from hexbench.artifacts.manifest import CheckpointError, entry_for, verify_checkpoint
from hexbench.errors import HexbenchError
from hexbench.world.env import ACTION_MODES, BASE_X_INDEX, OBS_DIM, STEER_MAX_TURN, TARGET_X_INDEX, action_size
from hexbench.world.sim import clip_ufunc

ALGOS: tuple[str, ...] = ("ppo", "sac", "td3")
ACTIVATIONS: tuple[str, ...] = ("relu", "tanh")
# Config fields that are not SB3 constructor arguments.
NON_SB3_FIELDS: frozenset[str] = frozenset({"algo", "action_mode", "net_arch", "activation", "residual_scale",
                                           "log_std_init", "action_noise_std", "early_end_penalty", "arrival_bonus",
                                           "normalize_reward", "initial_action", "decision_interval_steps",
                                           "critic_net_arch", "heading_hold", "end_terms_per_decision"})

# Fixed observation scaling (stateless, so a checkpoint is the network alone): joint velocities
# [rad/s] are divided by 5 to bring them to O(1) like the other groups (positions [rad], torques
# [N m], base pose [m, rad], target [m]).
OBS_SCALE = np.concatenate([
    np.ones(18), np.full(18, 0.2), np.ones(18), np.ones(3), np.ones(3), np.ones(2),
]).astype(np.float32)
assert OBS_SCALE.shape == (OBS_DIM,)


class ConfigError(HexbenchError, ValueError):
    """A baseline file's CONFIG is missing or invalid; the message is one line."""


def scale_observation(obs: np.ndarray) -> np.ndarray:
    return (np.asarray(obs, dtype=np.float32) * OBS_SCALE).astype(np.float32)


# ----------------------------------------------------------------------------- configs
def validate_config(config, where: str = "CONFIG") -> None:
    if config is None or not is_dataclass(config):
        raise ConfigError(f"{where}: expected a module-level CONFIG dataclass instance")
    names = {f.name for f in fields(config)}
    missing = sorted({"algo", "action_mode", "net_arch", "activation"} - names)
    if missing:
        raise ConfigError(f"{where}: CONFIG is not a training config (lacks field(s) {', '.join(missing)})")
    if config.algo not in ALGOS:
        raise ConfigError(f"{where}: algo {config.algo!r} unknown; valid: {', '.join(ALGOS)}")
    if config.action_mode not in ACTION_MODES:
        raise ConfigError(f"{where}: action_mode {config.action_mode!r} unknown; valid: {', '.join(ACTION_MODES)}")
    if config.activation not in ACTIVATIONS:
        raise ConfigError(f"{where}: activation {config.activation!r} unknown; valid: {', '.join(ACTIVATIONS)}")
    critic = getattr(config, "critic_net_arch", None)
    if critic is not None:
        if config.algo not in ("sac", "td3"):
            raise ConfigError(f"{where}: critic_net_arch is for algo 'sac' or 'td3' (separate critics), not {config.algo!r}")
        if not critic or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in critic):
            raise ConfigError(f"{where}: critic_net_arch must be positive layer sizes, e.g. (256, 256); got {critic!r}")
    interval = getattr(config, "decision_interval_steps", 1)
    if not isinstance(interval, int) or isinstance(interval, bool) or interval < 1:
        raise ConfigError(f"{where}: decision_interval_steps must be an integer >= 1 (control steps); got {interval!r}")
    if getattr(config, "heading_hold", False) and config.action_mode not in STEER_MAX_TURN:
        raise ConfigError(f"{where}: heading_hold needs a steering action_mode ({', '.join(STEER_MAX_TURN)}); "
                          f"got {config.action_mode!r}")
    initial_action = getattr(config, "initial_action", None)
    if initial_action is not None:
        n = policy_action_size(config)
        if config.algo != "ppo":
            raise ConfigError(f"{where}: initial_action is supported for algo 'ppo' only, not {config.algo!r}")
        if len(initial_action) != n or not all(-1.0 <= float(a) <= 1.0 for a in initial_action):
            raise ConfigError(f"{where}: initial_action must be {n} numbers in [-1, 1] for action_mode "
                              f"{config.action_mode!r}; got {tuple(initial_action)}")


def heading_hold(config) -> HeadingHold | None:
    """The heading law that sets the turn of a config with `heading_hold` (None: the policy acts alone)."""
    return HeadingHold() if getattr(config, "heading_hold", False) else None


def policy_action_size(config) -> int:
    """The number of values the config's policy outputs: its action mode's, less the turn a heading hold sets."""
    return action_size(config.action_mode) - (1 if heading_hold(config) is not None else 0)


def algo_class(algo: str):
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]


def policy_kwargs(config) -> dict:
    import torch.nn as nn

    activation = {"relu": nn.ReLU, "tanh": nn.Tanh}[config.activation]
    out = {"net_arch": list(config.net_arch), "activation_fn": activation}
    critic = getattr(config, "critic_net_arch", None)
    if critic is not None:  # SB3's off-policy form: the actor ("pi") and the critics ("qf") apart
        out["net_arch"] = {"pi": list(config.net_arch), "qf": list(critic)}
    if getattr(config, "log_std_init", None) is not None:
        out["log_std_init"] = float(config.log_std_init)
    return out


def sb3_kwargs(config) -> dict:
    """The config's SB3 constructor arguments (all fields except NON_SB3_FIELDS)."""
    out = {k: v for k, v in asdict(config).items() if k not in NON_SB3_FIELDS}
    for k, v in out.items():
        if isinstance(v, list):
            out[k] = tuple(v)
    return out


def action_noise(config):
    """SB3 action noise object for a config's optional `action_noise_std` (None when absent)."""
    std = getattr(config, "action_noise_std", None)
    if not std:
        return None
    from stable_baselines3.common.noise import NormalActionNoise

    n = policy_action_size(config)
    return NormalActionNoise(mean=np.zeros(n), sigma=np.full(n, float(std)))


def config_dict(config) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(config).items()}


def build_policy(config):
    """An untrained SB3 policy network with the config's architecture (for loading weights)."""
    import gymnasium as gym

    from hexbench.world.env import OBS_HIGH

    obs_space = gym.spaces.Box(-OBS_HIGH * OBS_SCALE, OBS_HIGH * OBS_SCALE, dtype=np.float32)
    act_space = gym.spaces.Box(-1.0, 1.0, (policy_action_size(config),), dtype=np.float32)
    cls = algo_class(config.algo)
    policy_cls = cls.policy_aliases["MlpPolicy"]
    # gSDE (a PPO constructor argument, which SB3 hands to its policy) changes the shape of log_std
    sde = {"use_sde": True} if getattr(config, "use_sde", False) else {}
    return policy_cls(obs_space, act_space, lambda _progress: 0.0, **policy_kwargs(config), **sde)


# ----------------------------------------------------------------------------- checkpoints
def load_policy_weights(path: Path, expected_sha256: str) -> dict:
    """Verify, then read the policy state_dict (tensors only; the pickled 'data' entry is skipped)."""
    from stable_baselines3.common.save_util import load_from_zip_file

    verify_checkpoint(path, expected_sha256)
    try:
        _data, params, _vars = load_from_zip_file(path, load_data=False, device="cpu")
    except Exception as e:  # noqa: BLE001 - any failure becomes one line
        raise CheckpointError(f"{path}: cannot be read as an SB3 checkpoint ({type(e).__name__}: {e})") from None
    if "policy" not in params:
        raise CheckpointError(f"{path}: holds no policy weights")
    return params["policy"]


def save_policy_weights(policy_state: dict, path: Path) -> str:
    """Write a policy-only SB3 zip (no pickled data) atomically; returns its sha256."""
    from stable_baselines3.common.save_util import save_to_zip_file

    with atomic_path(path) as tmp:
        save_to_zip_file(tmp, data=None, params={"policy": policy_state})
    return sha256_file(path)


# Parts of an SB3 policy that acting needs. PPO ships its whole policy (its value head is small);
# SAC's and TD3's critics (and their target copies) are three times the actor and serve learning only.
ACTING_PREFIXES: dict[str, tuple[str, ...]] = {"ppo": ("",), "sac": ("actor.",), "td3": ("actor.",)}


# Policy entries that only exploration uses (SB3 PPO's Gaussian log std).
EXPLORATION_KEYS: frozenset[str] = frozenset({"log_std"})


def acting_weights(algo: str, policy_state: dict) -> dict:
    """The entries of a policy state_dict that acting needs (what ships in baselines/checkpoints/)."""
    return {k: v for k, v in policy_state.items() if k.startswith(ACTING_PREFIXES[algo])}


def fit_weights(policy, state: dict, path: Path, needed) -> None:
    """Load `state` into `policy` (non-strict); CheckpointError unless every key with needed(key)
    is there and nothing is left over (a network of another shape)."""
    try:
        result = policy.load_state_dict(state, strict=False)
    except RuntimeError as e:
        first = str(e).splitlines()[0]
        raise CheckpointError(f"{path}: weights do not fit the config's network ({first})") from None
    missing = [k for k in result.missing_keys if needed(k)]
    if missing or result.unexpected_keys:
        what = f"missing {missing[0]}" if missing else f"unexpected {result.unexpected_keys[0]}"
        raise CheckpointError(f"{path}: weights do not fit the config's network ({what}; "
                              f"{len(missing)} missing, {len(result.unexpected_keys)} unexpected)")


def load_policy(config, path: Path, expected_sha256: str):
    """A policy of the config's network with the verified weights of `path` (full or acting-only)."""
    policy = build_policy(config)
    # PPO's log_std is exploration only: the deterministic policy never reads it, and its shape
    # depends on how it explored (a vector, or a matrix under gSDE), so it is not loaded
    state = {k: v for k, v in load_policy_weights(path, expected_sha256).items() if k not in EXPLORATION_KEYS}
    fit_weights(policy, state, path,
                needed=lambda k: k.startswith(ACTING_PREFIXES[config.algo]) and k not in EXPLORATION_KEYS)
    policy.set_training_mode(False)
    return policy


def shipped_checkpoint(checkpoints_dir: Path, method: str, terrain: str) -> tuple[Path, dict]:
    """(path, manifest entry) of the shipped weights for method x terrain; CheckpointError if none."""
    return entry_for(checkpoints_dir, f"{method}-{terrain}")


class PolicyController:
    """A trained SB3 policy behind the hexbench Controller protocol (deterministic actions)."""

    def __init__(self, action_mode: str, policy, checkpoint_sha256: str = "", checkpoint_path: Path | None = None,
                 target_horizon_m: float | None = None, decision_interval_steps: int = 1,
                 heading_hold: HeadingHold | None = None):
        self.action_mode = action_mode
        self.policy = policy
        self._actor = deterministic_actor(policy)
        # the policy decides every this many control steps and its action is held between (as it
        # trained: hexbench.training.wrappers.DecisionInterval)
        self.decision_interval_steps = max(1, int(decision_interval_steps))
        self._held: np.ndarray | None = None
        self._steps = 0
        # with a heading hold the policy chooses the gait and the hold the turn, every control step
        # (as it trained: hexbench.agents.heading.HeadingTurn)
        self.heading_hold = heading_hold
        # On a course longer than the training goal distance, the target the policy sees is held at
        # most this far ahead of the base (a waypoint on the way to the goal), as in training.
        self.target_horizon_m = target_horizon_m
        self.checkpoint_sha256 = checkpoint_sha256
        # the weights files behind this controller (result records list them with their sha256)
        self.checkpoint_paths = [Path(checkpoint_path)] if checkpoint_path is not None else []

    def reset(self, seed: int) -> None:  # deterministic policy: nothing to reseed; a new decision
        self._held, self._steps = None, 0

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self.decision_interval_steps > 1:
            if self._steps % self.decision_interval_steps == 0 or self._held is None:
                self._held = self._decide(obs)
            self._steps += 1
            action = self._held.copy()
        else:
            action = self._decide(obs)
        if self.heading_hold is not None:
            return with_held_heading(action, self.heading_hold, obs, self.action_mode)
        return action

    def _decide(self, obs: np.ndarray) -> np.ndarray:
        if self.target_horizon_m is not None:
            obs = np.array(obs, copy=True)
            obs[TARGET_X_INDEX] = min(obs[TARGET_X_INDEX], obs[BASE_X_INDEX] + self.target_horizon_m)
        action = self._actor(scale_observation(obs))
        return clip_ufunc(np.asarray(action, dtype=np.float64).reshape(-1), -1.0, 1.0)


def deterministic_action(policy, scaled_obs: np.ndarray) -> np.ndarray:
    """Bit for bit what `policy.predict(scaled_obs, deterministic=True)[0]` returns, for a single
    observation (`deterministic_actor`, made for this one call)."""
    return deterministic_actor(policy)(scaled_obs)


def deterministic_actor(policy):
    """scaled observation -> action: bit for bit what `policy.predict(scaled_obs, deterministic=True)[0]`
    returns for a single observation, at a fraction of its cost. predict switches the network's
    mode, checks and converts the observation and builds an action distribution on every call, and
    every layer is a module call. Here the same torch operations run on the same weight tensors in
    the same order (`actor_layers`: for PPO the distribution's mode is the action head's output;
    SAC's is tanh of the mean), so actions, and therefore every episode, are unchanged
    (tests/test_policy.py compares both on every shipped checkpoint). What does not depend on the
    observation (the layers, detached from autograd; the action bounds) is looked up once, here: a
    controller acts at every control step, in a process whose caches the physics has just evicted."""
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel, BasePolicy

    if not isinstance(policy, BasePolicy):  # any other object with SB3's predict signature
        return lambda scaled_obs: policy.predict(scaled_obs, deterministic=True)[0]
    shape, squash = policy.action_space.shape, policy.squash_output
    low, high = policy.action_space.low, policy.action_space.high
    layers = actor_layers(policy)
    if layers is not None:
        return _flat_actor(layers, shape, policy.unscale_action if squash else None, low, high)
    if isinstance(policy, ActorCriticPolicy):  # PPO: get_distribution(obs).mode(), the Gaussian's mean
        def forward(obs):
            features = BaseModel.extract_features(policy, obs, policy.pi_features_extractor)
            return policy.action_net(policy.mlp_extractor.forward_actor(features))
    else:  # SAC, TD3: the actor
        def forward(obs):
            return policy._predict(obs, deterministic=True)
    no_grad, as_tensor = torch.no_grad, torch.as_tensor

    def act(scaled_obs: np.ndarray) -> np.ndarray:
        with no_grad():
            action = forward(as_tensor(np.asarray(scaled_obs, dtype=np.float32)[None])).numpy().reshape(shape)
        return policy.unscale_action(action) if squash else clip_ufunc(action, low, high)

    return act


def _flat_actor(layers: list, shape: tuple, unscale, low: np.ndarray, high: np.ndarray):
    """The act function of `deterministic_actor` for a flat list of layers. Each linear layer is
    the `addmm(bias, x, weight.t())` that `torch.nn.functional.linear` calls for a 2-D input,
    written into a tensor of its own made once here, and each activation runs in place on it; the
    observation is copied into an input tensor made once too, and the action read from the last
    tensor's numpy view. The numbers are the same as the layers' own (tests/test_policy.py), with
    fewer and leaner calls into torch per action: no allocation, no autograd context (the weights
    are detached and no tensor here requires gradients), no conversion between numpy and torch."""
    import torch

    in_place = {torch.relu: torch.relu_, torch.tanh: torch.tanh_}
    linear = [weight for _op, weight, _bias in layers if weight is not None]
    first_in = linear[0].shape[1]
    observation = torch.zeros(1, first_in, dtype=torch.float32)
    result = observation
    steps: list = []
    for op, weight, bias in layers:
        if weight is None:
            steps.append((in_place[op], None, None, None))
        else:
            result = torch.zeros(1, weight.shape[0], dtype=torch.float32)
            steps.append((torch.addmm, bias.detach(), weight.detach().t(), result))
    observation_view, result_view = observation.numpy()[0], result.numpy().reshape(shape)
    copyto = np.copyto

    def act(scaled_obs: np.ndarray) -> np.ndarray:
        copyto(observation_view, scaled_obs, casting="same_kind")
        x = observation
        for op, bias, weight_t, out in steps:
            x = op(x) if bias is None else op(bias, x, weight_t, out=out)
        # a new array each call: the tensors above are overwritten by the next
        return unscale(result_view) if unscale is not None else clip_ufunc(result_view, low, high)

    return act


_ACTOR_LAYERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def actor_layers(policy) -> list | None:
    """The deterministic actor of an SB3 MLP policy as a flat list of (torch function, weight, bias)
    (weight None: an activation), in the order SB3 applies them; None for any other structure
    (then `deterministic_action` goes through the modules). The features extractor is left out:
    for a flat Box observation it is `float()` and `Flatten`, which change nothing of a float32
    (1, n) tensor. Built once per policy; the tensors are the policy's own."""
    if policy in _ACTOR_LAYERS:
        return _ACTOR_LAYERS[policy]
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    activations = {torch.nn.ReLU: torch.relu, torch.nn.Tanh: torch.tanh}

    def flat(*modules) -> list | None:
        out: list = []
        for module in modules:
            if isinstance(module, torch.nn.Sequential):
                inner = flat(*module)
                if inner is None:
                    return None
                out += inner
            elif type(module) is torch.nn.Linear:
                out.append((torch.nn.functional.linear, module.weight, module.bias))
            elif type(module) in activations:
                out.append((activations[type(module)], None, None))
            else:
                return None
        return out

    def flat_box(extractor) -> bool:
        space = policy.observation_space
        return type(extractor).__name__ == "FlattenExtractor" and type(space).__name__ == "Box" \
            and len(space.shape) == 1 and space.dtype == np.float32

    layers = None
    actor = getattr(policy, "actor", None)
    if isinstance(policy, ActorCriticPolicy):  # PPO: the Gaussian's mean is the action head's output
        if flat_box(policy.pi_features_extractor):
            layers = flat(policy.mlp_extractor.policy_net, policy.action_net)
    elif actor is not None and flat_box(getattr(actor, "features_extractor", None)):
        if hasattr(actor, "latent_pi") and not getattr(actor, "use_sde", False):  # SAC: tanh of the mean
            head = flat(actor.latent_pi, actor.mu)
            layers = None if head is None else head + [(torch.tanh, None, None)]
        elif not hasattr(actor, "latent_pi"):  # TD3: mu ends in its tanh
            layers = flat(actor.mu)
    _ACTOR_LAYERS[policy] = layers
    return layers


# Courses without weights of their own and the policy that walks them: the mixed course gets the
# rough-terrain policy (paper Table 5 runs the rough model on slopes and stairs the same way).
POLICY_TERRAIN: dict[str, str] = {"mixed": "rough"}
# Policies train with the goal 2.5 m ahead (paper 4.1); on a longer course (the mixed course, 6.3 m)
# they see a waypoint at most this far ahead of the base instead of a goal they never met in training.
TRAINING_GOAL_DISTANCE_M = 2.5


def waypoint_horizon_m(goal_distance_m: float) -> float | None:
    """How far ahead of the base a policy sees its target on a course of this goal distance [m].

    None (the goal itself) unless the course is longer than training's; the one rule for every
    policy controller, the HLTA's terrain policies included.
    """
    return TRAINING_GOAL_DISTANCE_M if goal_distance_m > TRAINING_GOAL_DISTANCE_M else None


def make_policy_controller(config, checkpoints_dir: Path, method: str, task,
                           weights_terrain: str | None = None) -> PolicyController:
    """What a baseline file's make_controller(task) returns: its shipped weights for the task.

    The weights are those of `weights_terrain` if given, else of the task's terrain (POLICY_TERRAIN
    for a course without weights of its own); the target horizon follows the task's goal distance.
    """
    import torch

    torch.set_num_threads(1)
    validate_config(config, method)
    terrain = weights_terrain or POLICY_TERRAIN.get(task.terrain, task.terrain)
    path, entry = shipped_checkpoint(checkpoints_dir, method, terrain)
    policy = load_policy(config, path, entry["sha256"])
    return PolicyController(config.action_mode, policy, entry["sha256"], path, waypoint_horizon_m(task.goal_distance_m),
                            getattr(config, "decision_interval_steps", 1), heading_hold(config))
