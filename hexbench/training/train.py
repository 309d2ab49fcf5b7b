"""Training a baseline file on a terrain's curriculum with Stable-Baselines3 (`hexbench train`).

    hexbench train baselines/ppo_cpg.py --terrain rough --steps 1000000 --seed 0 --workers 2

The baseline file's CONFIG (see hexbench.agents.policy) picks the algorithm, action mode and
hyper-parameters. Environments are the paper's training curriculum (section 4.1: level up after
20 arrivals, reward times (1 + delta), observation noise), one per worker: SubprocVecEnv for W > 1,
DummyVecEnv for W = 1. Everything of a run lives in its directory (default
training/<method>-<terrain>-seed<S>/):

    run.json             what was run (command, config, seed, budget, commit) + every checkpoint
                         with its sha256, env steps, wall time and metrics; the curriculum state
    progress.csv         one row per env every `csv_every_s`: env_steps, wall_time_s, env_index,
                         episodes, mean_episode_reward, success_rate (last 20 episodes of that env),
                         curriculum_level, curriculum_successes
    checkpoints/step_<N>.zip   full SB3 models (for resuming), every `checkpoint_every_s`
    train.log            (when started in the background with output redirected)

Running the same command again resumes from the last checkpoint (sha256 checked against run.json
first), with the curriculum level of every env restored; --steps is the total budget, not the
remainder. Off-policy methods (SAC, TD3) resume with an empty replay buffer: buffers are large and
pickled, so they are not saved. SIGINT / SIGTERM save a checkpoint before exiting.

A config with `normalize_reward = True` trains on rewards divided by a running estimate of the
discounted return's standard deviation (SB3's VecNormalize, rewards only; observations keep the
fixed OBS_SCALE, so a checkpoint is still the network alone). Why: the Table 1 returns are in the
hundreds to thousands, and SB3 clips the *joint* gradient norm of policy and value loss at
`max_grad_norm` (0.5). Measured on the rough PPO-CPG run (checkpoint 180,502, one minibatch): the
value-loss gradient norm was 2,556 against the policy loss's 5.7, so clipping scaled the policy
gradient by 0.0002 and the policy barely learned (its std went 0.368 -> 0.345 in 830k steps). The
normaliser's statistics are stored with every checkpoint in run.json (plain numbers, no pickle)
and restored on resume. Episode rewards in progress.csv stay the raw Table 1 returns.

`--init-from baselines/checkpoints/<method>-<terrain>.zip` starts a new PPO run from shipped
weights (verified against their manifest before anything is written): the actor is taken over, the
exploration std comes from the config and the value function starts fresh (the source run may
have had another reward scale). run.json records the source file, sha256 and env steps, so a
fine-tuned policy's total budget is the source's env steps plus the run's.

`--value-warmup N` (PPO) holds the actor and its std fixed as initialised, taken over by --init-from
or fresh, for the first N env steps, so that the first updates train the fresh value function only
(make_value_warmup). A fresh PPO-CPG actor's mean residual is about 0, so a warm-up from scratch
holds the open-loop CPG plus exploration noise while the value function learns what it earns.

`--curriculum START:STEP:TOP` replaces the paper's curriculum of the terrain with another one
(same rule: level up after 20 arrivals; levels in the paper's units), e.g. slopes 18:0.5:21 to
fine-tune beyond the paper's 18-deg top; run.json records it as `curriculum_levels`. `--level L`
trains at one suite level instead; the two exclude each other.
"""

from __future__ import annotations

import ast
import csv
import json
import math
import signal
import time
from collections import deque
from dataclasses import asdict, dataclass, fields, replace
from datetime import datetime, timezone
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np

from hexbench.agents.policy import (
    OBS_SCALE,
    ConfigError,
    action_noise,
    algo_class,
    config_dict,
    policy_kwargs,
    sb3_kwargs,
    validate_config,
)
from hexbench.artifacts.files import sha256_file, write_json_atomic
from hexbench.artifacts.manifest import MANIFEST_NAME, CheckpointError, read_manifest, verify_checkpoint, write_entry
from hexbench.artifacts.provenance import git_commit
from hexbench.world.env import OBS_HIGH, Curriculum, HexapodEnv

TRAIN_TERRAINS: tuple[str, ...] = ("rough", "slopes", "stairs")
METRICS_WINDOW_EPISODES = 20
CSV_COLUMNS = ("env_steps", "wall_time_s", "env_index", "episodes", "mean_episode_reward", "success_rate",
               "curriculum_level", "curriculum_successes")


TRAIN_DEVICES: tuple[str, ...] = ("cpu", "cuda")


class TrainError(Exception):
    """Bad training input or state; the message is one line."""


# --------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class TrainSettings:
    baseline_path: Path
    terrain: str
    total_steps: int  # env steps, summed over workers
    seed: int = 0
    workers: int = 1
    out_dir: Path | None = None  # None -> training/<method>-<terrain>-seed<seed>
    checkpoint_every_s: float = 300.0
    csv_every_s: float = 60.0
    overrides: tuple[tuple[str, object], ...] = ()  # config field overrides (name, value)
    command: str = ""
    show_progress: bool = True
    fixed_level: float | None = None  # train at one suite level without the curriculum (--level; epsilon sweep)
    device: str = "cpu"  # torch device of the learner ("cpu" or "cuda"); envs always step on the CPU
    init_from: Path | None = None  # shipped weights (baselines/checkpoints/<method>-<terrain>.zip) to start from
    curriculum: Curriculum | None = None  # replaces the paper's curriculum for the terrain (--curriculum)
    value_warmup_steps: int = 0  # PPO: env steps during which only the value function learns

    @property
    def method(self) -> str:
        return Path(self.baseline_path).stem

    @property
    def run_dir(self) -> Path:
        return Path(self.out_dir) if self.out_dir else Path("training") / f"{self.method}-{self.terrain}-seed{self.seed}"


def parse_curriculum(text: str) -> Curriculum:
    """'18:0.5:21' -> Curriculum(18.0, 0.5, 21.0): start level, level step, top level, in the paper's units."""
    parts = text.split(":")
    try:
        start, step, top = (float(p) for p in parts)
    except ValueError:
        raise TrainError(f"--curriculum {text!r} is not START:STEP:TOP (three numbers in the terrain's unit, "
                         f"e.g. 18:0.5:21)") from None
    if not (step > 0 and start <= top and start >= 0 and all(math.isfinite(v) for v in (start, step, top))):
        raise TrainError(f"--curriculum {text!r}: needs 0 <= START <= TOP and STEP > 0")
    return Curriculum(start, step, top)


def parse_override(text: str) -> tuple[str, object]:
    """'learning_rate=3e-4' -> ('learning_rate', 0.0003); values are Python literals or bare strings."""
    if "=" not in text:
        raise TrainError(f"override {text!r} is not NAME=VALUE")
    name, raw = text.split("=", 1)
    try:
        value = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        value = raw
    return name.strip(), value


def load_baseline_config(path: Path, overrides: tuple[tuple[str, object], ...] = ()):
    """The CONFIG of a baseline file, with overrides applied and validated."""
    from hexbench.suite.controller import ControllerError, load_controller_module

    try:
        module = load_controller_module(path)
    except ControllerError as e:
        raise TrainError(str(e)) from None
    config = getattr(module, "CONFIG", None)
    try:
        validate_config(config, str(path))
    except ConfigError as e:
        raise TrainError(str(e)) from None
    if overrides:
        names = {f.name for f in fields(config)}
        for name, _ in overrides:
            if name not in names:
                raise TrainError(f"{path}: config has no field {name!r}; fields: {', '.join(sorted(names))}")
        config = replace(config, **dict(overrides))
        try:
            validate_config(config, str(path))
        except ConfigError as e:
            raise TrainError(str(e)) from None
    return config


# --------------------------------------------------------------------------- environments
class TrainingWrapper(gym.ObservationWrapper):
    """Fixed observation scaling (hexbench.agents.policy.OBS_SCALE) and access to the curriculum state."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.observation_space = gym.spaces.Box(-OBS_HIGH * OBS_SCALE, OBS_HIGH * OBS_SCALE, dtype=np.float32)

    def observation(self, observation):
        return (observation * OBS_SCALE).astype(np.float32)

    def curriculum_state(self) -> dict:
        env = self.env.unwrapped
        return {"level": float(env.level), "successes": int(env.curriculum_successes)}

    def set_curriculum_state(self, level: float, successes: int) -> None:
        env = self.env.unwrapped
        env.level = float(level)
        env.curriculum_successes = int(successes)


def make_training_env(terrain: str, action_mode: str, residual_scale: float | None,
                      fixed_level: float | None = None, early_end_penalty: bool = False,
                      curriculum: Curriculum | None = None) -> gym.Env:
    """The curriculum env of paper 4.1 (or another curriculum, or with fixed_level that level alone),
    noise on, monitored."""
    from stable_baselines3.common.monitor import Monitor

    from hexbench.suite.tasks import curriculum_config
    from hexbench.world.env import EnvConfig

    if fixed_level is None:
        config = curriculum_config(terrain, action_mode, residual_scale=residual_scale,
                                   early_end_penalty=early_end_penalty)
        if curriculum is not None:
            config = replace(config, curriculum=curriculum)
    else:
        config = EnvConfig(terrain=terrain, level=fixed_level, action_mode=action_mode, residual_scale=residual_scale,
                           early_end_penalty=early_end_penalty)
    return TrainingWrapper(Monitor(HexapodEnv(config)))


def make_vec_env(terrain: str, action_mode: str, workers: int, residual_scale: float | None = None,
                 fixed_level: float | None = None, early_end_penalty: bool = False,
                 normalize_reward_gamma: float | None = None, curriculum: Curriculum | None = None):
    """The workers' envs as one VecEnv; with normalize_reward_gamma, rewards are normalised (VecNormalize)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    factories = [partial(make_training_env, terrain, action_mode, residual_scale, fixed_level, early_end_penalty,
                         curriculum) for _ in range(workers)]
    venv = DummyVecEnv(factories) if workers == 1 else SubprocVecEnv(factories, start_method="fork")
    if normalize_reward_gamma is None:
        return venv
    return VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=normalize_reward_gamma)


def reward_normalizer_state(venv) -> dict | None:
    """The running return statistics of a reward-normalising VecEnv (None for a plain one)."""
    from stable_baselines3.common.vec_env import VecNormalize

    if not isinstance(venv, VecNormalize):
        return None
    rms = venv.ret_rms
    return {"mean": float(np.asarray(rms.mean)), "var": float(np.asarray(rms.var)), "count": float(rms.count)}


def restore_reward_normalizer(venv, state: dict | None) -> None:
    from stable_baselines3.common.vec_env import VecNormalize

    if isinstance(venv, VecNormalize) and state:
        venv.ret_rms.mean = np.float64(state["mean"])
        venv.ret_rms.var = np.float64(state["var"])
        venv.ret_rms.count = float(state["count"])


def set_initial_action(model, initial_action) -> None:
    """Start a new PPO policy's mean action at initial_action (its output layer's bias).

    SB3 initialises the action layer with tiny weights (orthogonal, gain 0.01) and zero bias, so a
    fresh policy's mean action is about 0 whatever the observation; the bias moves that starting
    point. HRL uses it to start from the CPG's own gait instead of the middle of the parameter
    ranges, where the hip does not swing and the robot does not walk (baselines/hrl.py).
    """
    import torch

    with torch.no_grad():
        model.policy.action_net.bias.copy_(torch.as_tensor(initial_action, dtype=torch.float32))


# Weights a warm start (`--init-from`) does not take over: the exploration std comes from the config
# (the point of fine-tuning at another std), and the value function is learned afresh because the
# source run's returns may have had another scale (it may have trained without reward normalisation).
FRESH_ON_INIT_PREFIXES: tuple[str, ...] = ("log_std", "value_net.", "mlp_extractor.value_net.")
VALUE_PREFIXES: tuple[str, ...] = ("value_net.", "mlp_extractor.value_net.")


def make_value_warmup(warmup_steps: int):
    """A callback that holds the actor (and its std) fixed until `warmup_steps` env steps, so the first
    PPO updates fit the fresh value function instead of moving the actor (taken over by a warm start,
    or fresh) by advantages from a value function that knows nothing yet. Parameters without a
    gradient are left alone by the optimiser; resuming before the end of the warm-up freezes them again."""
    from stable_baselines3.common.callbacks import BaseCallback

    class ValueWarmup(BaseCallback):
        def actor_parameters(self):
            return [p for name, p in self.model.policy.named_parameters() if not name.startswith(VALUE_PREFIXES)]

        def _on_training_start(self) -> None:
            self.frozen = self.num_timesteps < warmup_steps
            for p in self.actor_parameters():
                p.requires_grad_(not self.frozen)

        def _on_rollout_end(self) -> None:  # the update follows: the actor learns from rollouts past warmup_steps
            if self.frozen and self.model.num_timesteps > warmup_steps:
                for p in self.actor_parameters():
                    p.requires_grad_(True)
                self.frozen = False

        def _on_step(self) -> bool:
            return True

    return ValueWarmup()


def read_init_weights(path: Path, config) -> tuple[dict, dict]:
    """(weights to load, what they are) for a warm start from a shipped checkpoint, checked to fit config's network.

    The file must sit beside a manifest.json that lists it (it is hashed against that entry before
    anything is read, as for every shipped checkpoint). Only PPO: a shipped SAC/TD3 file holds the
    actor alone, and a critic learned from nothing would undo it before it could help.
    """
    from hexbench.agents.policy import build_policy, fit_weights, load_policy_weights

    path = Path(path)
    if config.algo != "ppo":
        raise TrainError(f"--init-from works for PPO baselines only (this config's algo is {config.algo!r})")
    try:
        manifest = read_manifest(path.parent)
    except CheckpointError as e:
        raise TrainError(f"--init-from {path}: {e}") from None
    entries = {e.get("file"): (key, e) for key, e in manifest["checkpoints"].items()}
    if path.name not in entries:
        raise TrainError(f"--init-from {path}: not listed in {path.parent / MANIFEST_NAME}; "
                         f"listed: {', '.join(sorted(f for f in entries if f))}")
    key, entry = entries[path.name]
    try:
        state = load_policy_weights(path, entry["sha256"])
    except CheckpointError as e:
        raise TrainError(str(e)) from None
    kept = {k: v for k, v in state.items() if not k.startswith(FRESH_ON_INIT_PREFIXES)}
    try:
        fit_weights(build_policy(config), kept, path, needed=lambda k: not k.startswith(FRESH_ON_INIT_PREFIXES))
    except CheckpointError as e:
        raise TrainError(f"--init-from {e}") from None
    info = {"file": str(path), "manifest_key": key, "sha256": entry["sha256"],
            "source_env_steps": entry.get("env_steps"), "source_command": entry.get("command"),
            "fresh": list(FRESH_ON_INIT_PREFIXES)}
    return kept, info


# --------------------------------------------------------------------------- run directory


def read_run(run_dir: Path) -> dict | None:
    path = Path(run_dir) / "run.json"
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise TrainError(f"{path}: not valid JSON ({e.msg}); move the run directory away to start afresh") from None


def best_checkpoint(run: dict) -> dict:
    """The best checkpoint of a run: highest mean curriculum level, then success rate, then reward."""
    if not run.get("checkpoints"):
        raise TrainError("run has no checkpoints yet")

    def key(c):
        reward = c.get("mean_episode_reward")
        return (c.get("curriculum_level_mean") or 0.0, c.get("success_rate") or 0.0,
                reward if reward is not None else -math.inf, c["env_steps"])
    return max(run["checkpoints"], key=key)


# --------------------------------------------------------------------------- monitoring callback
def _nan_to_none(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def make_callback(settings: TrainSettings, run: dict, model_saver, progress=None, task=None, console=None):
    from stable_baselines3.common.callbacks import BaseCallback

    class TrainingMonitor(BaseCallback):
        """Per-env episode stats, the progress bar, the CSV and periodic checkpoints."""

        def __init__(self):
            super().__init__()
            n = settings.workers
            self.returns = [deque(maxlen=METRICS_WINDOW_EPISODES) for _ in range(n)]
            self.successes = [deque(maxlen=METRICS_WINDOW_EPISODES) for _ in range(n)]
            self.episodes = [0] * n
            self.wall_offset_s = float(run.get("wall_time_s", 0.0))
            self.t0 = time.monotonic()
            self.last_csv = self.t0
            self.last_ckpt = self.t0
            self.start_steps = None
            self.reward_sum = 0.0  # summed step rewards of this session, all envs
            self.reward_steps = 0

        def wall_time_s(self) -> float:
            return self.wall_offset_s + time.monotonic() - self.t0

        def _on_training_start(self) -> None:
            self.start_steps = self.num_timesteps
            self.t0 = time.monotonic()
            self.last_csv = self.last_ckpt = self.t0

        def _on_step(self) -> bool:
            # raw Table 1 rewards, also when the learner sees normalised ones
            env = self.training_env
            rewards = env.get_original_reward() if hasattr(env, "get_original_reward") else self.locals["rewards"]
            self.reward_sum += float(np.sum(rewards))
            self.reward_steps += len(rewards)
            for i, info in enumerate(self.locals["infos"]):
                ep = info.get("episode")
                if ep is not None:
                    self.episodes[i] += 1
                    self.returns[i].append(float(ep["r"]))
                    self.successes[i].append(bool(info.get("is_success", False)))
            now = time.monotonic()
            if progress is not None and self.n_calls % 20 == 0:
                self._update_progress(now)
            if now - self.last_ckpt >= settings.checkpoint_every_s:
                self.checkpoint()
            elif now - self.last_csv >= settings.csv_every_s:
                self.write_csv()
            return True

        def _update_progress(self, now: float) -> None:
            rate = (self.num_timesteps - self.start_steps) / max(now - self.t0, 1e-9)
            s = self.summary()
            sr = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.0f}%"
            rw = "-" if s["mean_episode_reward"] is None else f"{s['mean_episode_reward']:.0f}"
            progress.update(task, completed=self.num_timesteps,
                            info=f"{rate:.0f} steps/s  level {s['curriculum_level_mean']:g}  success {sr}  reward {rw}  "
                                 f"episodes {sum(self.episodes)}")

        def curriculum(self) -> list[dict]:
            return self.training_env.env_method("curriculum_state")

        def summary(self, curriculum: list[dict] | None = None) -> dict:
            all_r = [r for q in self.returns for r in q]
            all_s = [s for q in self.successes for s in q]
            levels = [c["level"] for c in curriculum] if curriculum else [
                float(info.get("level", math.nan)) for info in self.locals.get("infos", [])] or [math.nan]
            return {
                "mean_episode_reward": float(np.mean(all_r)) if all_r else None,
                "success_rate": float(np.mean(all_s)) if all_s else None,
                "episodes": int(sum(self.episodes)),
                "mean_step_reward": self.reward_sum / self.reward_steps if self.reward_steps else None,
                "curriculum_level_mean": float(np.mean(levels)),
                "curriculum_level_max": float(np.max(levels)),
            }

        def write_csv(self, curriculum: list[dict] | None = None) -> None:
            if self.num_timesteps == getattr(self, "last_csv_steps", None):
                return  # a checkpoint right after a CSV row: no duplicate rows
            self.last_csv_steps = self.num_timesteps
            curriculum = curriculum or self.curriculum()
            path = settings.run_dir / "progress.csv"
            new = not path.exists()
            wall = self.wall_time_s()
            with open(path, "a", newline="") as f:
                w = csv.writer(f)
                if new:
                    w.writerow(CSV_COLUMNS)
                for i, cur in enumerate(curriculum):
                    r = np.mean(self.returns[i]) if self.returns[i] else math.nan
                    s = np.mean(self.successes[i]) if self.successes[i] else math.nan
                    w.writerow([self.num_timesteps, f"{wall:.1f}", i, self.episodes[i],
                                "" if math.isnan(r) else f"{r:.3f}", "" if math.isnan(s) else f"{s:.3f}",
                                f"{cur['level']:g}", cur["successes"]])
            self.last_csv = time.monotonic()
            if console is not None:
                s = self.summary(curriculum)
                console.log(f"{self.num_timesteps} env steps, {wall:.0f} s: reward {s['mean_episode_reward']}, "
                            f"success {s['success_rate']}, level {[c['level'] for c in curriculum]}")

        def checkpoint(self) -> None:
            curriculum = self.curriculum()
            self.write_csv(curriculum)
            model_saver(self.model, self.num_timesteps, self.wall_time_s(), curriculum,
                        self.summary(curriculum), self.episodes)
            self.last_ckpt = time.monotonic()

    return TrainingMonitor()


# --------------------------------------------------------------------------- main entry
def train(settings: TrainSettings) -> dict:
    """Train (or resume) a run; returns the final run.json content."""
    import torch

    torch.set_num_threads(1)
    if settings.terrain not in TRAIN_TERRAINS:
        raise TrainError(f"unknown terrain {settings.terrain!r}; valid terrains: {', '.join(TRAIN_TERRAINS)}")
    if settings.workers < 1:
        raise TrainError(f"--workers must be >= 1 (got {settings.workers})")
    if settings.total_steps < 1:
        raise TrainError(f"--steps must be >= 1 (got {settings.total_steps})")
    if settings.device not in TRAIN_DEVICES:
        raise TrainError(f"unknown --device {settings.device!r}; valid: {', '.join(TRAIN_DEVICES)}")
    if settings.device == "cuda" and not torch.cuda.is_available():
        raise TrainError("--device cuda: this torch sees no CUDA GPU (torch.cuda.is_available() is False); use --device cpu")
    if settings.fixed_level is not None:
        from hexbench.suite.tasks import load_suite

        try:
            load_suite().task(settings.terrain, settings.fixed_level)
        except ValueError as e:
            raise TrainError(f"--level: {e}") from None
        if settings.curriculum is not None:
            raise TrainError("--level and --curriculum exclude each other (one level, or a curriculum of levels)")
    if settings.value_warmup_steps < 0:
        raise TrainError(f"--value-warmup needs a number of env steps >= 0 (got {settings.value_warmup_steps})")
    config = load_baseline_config(Path(settings.baseline_path), settings.overrides)
    if settings.value_warmup_steps and config.algo != "ppo":
        raise TrainError(f"--value-warmup works for PPO baselines only, which learn a value function "
                         f"beside the actor (this config's algo is {config.algo!r})")
    run_dir = settings.run_dir
    previous = read_run(run_dir)
    cfg_dict = config_dict(config)
    if previous is not None:
        # a config field added after the run started is absent from its run.json: it resumes only with
        # that field off (False / None), which is how the run was trained
        recorded = {**previous, "config": {**{k: v for k, v in cfg_dict.items() if not v}, **previous.get("config", {})},
                    "init_from": (previous.get("init_from") or {}).get("file")}  # compared by source file
        for key, now in (("method", settings.method), ("terrain", settings.terrain), ("seed", settings.seed),
                         ("workers", settings.workers), ("config", cfg_dict),
                         ("fixed_level", settings.fixed_level),
                         ("curriculum_levels", asdict(settings.curriculum) if settings.curriculum else None),
                         ("value_warmup_steps", settings.value_warmup_steps or None),
                         ("init_from", str(settings.init_from) if settings.init_from else None)):
            was = recorded.get(key)
            if was != now:
                raise TrainError(f"{run_dir}: holds a run with {key}={was!r}, not {now!r}; "
                                 f"choose another --out or move it away")
    init_weights = None
    if settings.init_from is not None and previous is None:  # read (and verify) before any file is written
        init_weights = read_init_weights(settings.init_from, config)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "checkpoints").mkdir(exist_ok=True)
    run = previous or {
        "method": settings.method, "baseline_file": str(settings.baseline_path),
        "baseline_sha256": sha256_file(settings.baseline_path), "terrain": settings.terrain,
        "seed": settings.seed, "workers": settings.workers, "config": cfg_dict, "fixed_level": settings.fixed_level,
        "started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "hexbench_commit": git_commit(),
        "wall_time_s": 0.0, "env_steps": 0, "checkpoints": [], "curriculum": None, "sessions": [],
        "init_from": init_weights[1] if init_weights else None,
        "curriculum_levels": asdict(settings.curriculum) if settings.curriculum else None,
        "value_warmup_steps": settings.value_warmup_steps or None,
    }
    run["total_steps"] = settings.total_steps
    run["command"] = settings.command
    run["sessions"].append({"started_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                            "command": settings.command, "hexbench_commit": git_commit(),
                            "from_env_steps": run["env_steps"]})
    write_json_atomic(run_dir / "run.json", run)

    venv = make_vec_env(settings.terrain, config.action_mode, settings.workers, config.residual_scale,
                        settings.fixed_level, getattr(config, "early_end_penalty", False),
                        config.gamma if getattr(config, "normalize_reward", False) else None, settings.curriculum)
    cls = algo_class(config.algo)
    if run["checkpoints"]:
        last = run["checkpoints"][-1]
        path = run_dir / last["file"]

        try:
            verify_checkpoint(path, last["sha256"])
        except CheckpointError as e:
            venv.close()
            raise TrainError(str(e)) from None
        extra = {"action_noise": action_noise(config)} if action_noise(config) is not None else {}
        model = cls.load(path, env=venv, device=settings.device, **extra)
        restore_reward_normalizer(venv, last.get("reward_normalizer"))
        if run["curriculum"]:
            for i, cur in enumerate(run["curriculum"]):
                venv.env_method("set_curriculum_state", cur["level"], cur["successes"], indices=[i])
    else:
        extra = {"action_noise": action_noise(config)} if action_noise(config) is not None else {}
        model = cls("MlpPolicy", venv, seed=settings.seed, device=settings.device, verbose=0,
                    policy_kwargs=policy_kwargs(config), **sb3_kwargs(config), **extra)
        if getattr(config, "initial_action", None) is not None:
            set_initial_action(model, config.initial_action)
        if init_weights is not None:
            model.policy.load_state_dict(init_weights[0], strict=False)  # fit checked by read_init_weights

    def save_checkpoint(model, env_steps: int, wall_time_s: float, curriculum: list[dict], summary: dict,
                        episodes: list[int]) -> None:
        name = f"checkpoints/step_{env_steps:010d}.zip"
        path = run_dir / name
        tmp = path.with_name(path.stem + ".tmp.zip")
        model.save(tmp)
        tmp.replace(path)
        entry = {"file": name, "sha256": sha256_file(path), "env_steps": int(env_steps),
                 "wall_time_s": round(wall_time_s, 1), "saved_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                 **{k: _nan_to_none(v) if isinstance(v, float) else v for k, v in summary.items()}}
        normalizer = reward_normalizer_state(venv)
        if normalizer is not None:
            entry["reward_normalizer"] = normalizer
        run["checkpoints"] = [c for c in run["checkpoints"] if c["file"] != name] + [entry]
        run["env_steps"] = int(env_steps)
        run["wall_time_s"] = round(wall_time_s, 1)
        run["curriculum"] = curriculum
        write_json_atomic(run_dir / "run.json", run)

    remaining = settings.total_steps - model.num_timesteps
    if remaining <= 0:
        venv.close()
        return run

    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    console = Console(stderr=True)
    progress = Progress(TextColumn(f"[bold]{settings.method} {settings.terrain} seed {settings.seed}"), BarColumn(),
                        MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[info]}"),
                        console=console, disable=not settings.show_progress, transient=False)
    task = progress.add_task("train", total=settings.total_steps, completed=model.num_timesteps, info="starting")
    callback = make_callback(settings, run, save_checkpoint, progress, task,
                             console if not console.is_terminal else None)

    def on_sigterm(signum, frame):
        raise KeyboardInterrupt

    old_handler = signal.signal(signal.SIGTERM, on_sigterm)
    interrupted = False
    try:
        with progress:
            model.learn(total_timesteps=remaining, reset_num_timesteps=False,
                        callback=[callback, make_value_warmup(settings.value_warmup_steps)]
                        if settings.value_warmup_steps else callback)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        signal.signal(signal.SIGTERM, old_handler)
    if callback.model is not None and callback.model.num_timesteps > (run["env_steps"] or 0):
        callback.num_timesteps = callback.model.num_timesteps
        try:
            callback.checkpoint()
        except (EOFError, BrokenPipeError, ConnectionError) as e:  # worker processes already gone
            console.print(f"final checkpoint not saved ({type(e).__name__}); last one is at {run['env_steps']} steps")
    venv.close()
    if interrupted:
        raise TrainError(f"interrupted at {run['env_steps']} env steps; checkpoint saved in {run_dir} "
                         f"(run the same command to resume)")
    return run


# --------------------------------------------------------------------------- publishing
def checkpoint_at(run_dir: Path, run: dict, env_steps: str, other_choices: tuple[str, ...] = ()) -> dict:
    """The run's checkpoint at `env_steps` (as typed); a one-line TrainError naming the valid choices if none."""
    for c in run["checkpoints"]:
        if str(c["env_steps"]) == env_steps:
            return c
    valid = ", ".join([*other_choices, *(str(c["env_steps"]) for c in run["checkpoints"])])
    raise TrainError(f"{run_dir}: no checkpoint {env_steps!r}; valid: {valid}")


def publish_checkpoint(run_dir: Path, dest_dir: Path, which: str = "best") -> dict:
    """Copy a run's checkpoint (best, last, or a step count) as shipped policy-only weights.

    Writes <dest_dir>/<method>-<terrain>.zip (policy state_dict only, no pickled data) and its entry
    in <dest_dir>/manifest.json: sha256, command, env-step budget and steps reached, seed, wall
    time, hexbench commit, metrics at that checkpoint and whether the run was complete. A run
    warm-started with --init-from counts its source's env steps in env_steps and the budget, and
    keeps the source (file, sha256, command) under init_from.
    """
    from hexbench.agents.policy import acting_weights, load_policy_weights, save_policy_weights

    run_dir, dest_dir = Path(run_dir), Path(dest_dir)
    run = read_run(run_dir)
    if run is None:
        raise TrainError(f"{run_dir}: no run.json (not a training run directory)")
    if not run.get("checkpoints"):
        raise TrainError(f"{run_dir}: run has no checkpoints yet")
    if which == "best":
        chosen = best_checkpoint(run)
    elif which == "heldout":
        from hexbench.training.selection import SelectionError, heldout_best

        try:
            chosen = heldout_best(run_dir, run)
        except SelectionError as e:
            raise TrainError(str(e)) from None
    elif which == "last":
        chosen = run["checkpoints"][-1]
    else:
        chosen = checkpoint_at(run_dir, run, which, other_choices=("best", "heldout", "last"))
    try:
        state = load_policy_weights(run_dir / chosen["file"], chosen["sha256"])
    except CheckpointError as e:
        raise TrainError(str(e)) from None
    dest_dir.mkdir(parents=True, exist_ok=True)
    key = f"{run['method']}-{run['terrain']}"
    sha = save_policy_weights(acting_weights(run["config"]["algo"], state), dest_dir / f"{key}.zip")
    complete = run["env_steps"] >= run["total_steps"]  # the run reached its budget
    entry = {
        "file": f"{key}.zip", "sha256": sha, "method": run["method"], "terrain": run["terrain"],
        "algo": run["config"]["algo"], "action_mode": run["config"]["action_mode"], "seed": run["seed"],
        "command": run["sessions"][0]["command"] if run.get("sessions") else run.get("command", ""),
        "env_step_budget": run["total_steps"], "env_steps": chosen["env_steps"],
        "wall_time_s": chosen["wall_time_s"], "workers": run["workers"],
        "hexbench_commit": run["hexbench_commit"], "baseline_sha256": run["baseline_sha256"],
        "source_checkpoint_sha256": chosen["sha256"], "complete": complete,
        "status": (f"checkpoint at {chosen['env_steps']} env steps ({which}) of a complete run of {run['env_steps']} steps"
                   if complete else
                   f"PARTIAL run: checkpoint ({which}) at {chosen['env_steps']} of {run['total_steps']} env steps"),
        "metrics_at_checkpoint": {k: chosen.get(k) for k in ("mean_episode_reward", "success_rate", "episodes",
                                                             "curriculum_level_mean", "curriculum_level_max")},
        "published_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    source = run.get("init_from")
    if source:  # a warm-started run: count the source's training too, and say where it came from
        before = int(source.get("source_env_steps") or 0)
        entry["init_from"] = source
        entry["run_env_steps"] = chosen["env_steps"]
        entry["env_steps"] = before + chosen["env_steps"]
        entry["env_step_budget"] = before + run["total_steps"]
        entry["status"] += f"; warm-started from {source['manifest_key']} at {before} env steps ({entry['env_steps']} in all)"
    from hexbench.training.selection import selection_summary

    selection = selection_summary(run_dir, chosen["sha256"])
    if selection is not None:  # how the shipped checkpoint did on held-out episodes, whoever chose it
        entry["selection"] = selection
    return write_entry(dest_dir, key, entry)
