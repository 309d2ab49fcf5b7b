"""Starting a run from somewhere other than scratch, and holding the actor while the critic learns.

`--init-from baselines/checkpoints/<method>-<terrain>.zip` starts a new PPO run from shipped
weights (verified against their manifest before anything is written): the actor is taken over, the
exploration std comes from the config and the value function starts fresh (the source run may
have had another reward scale). run.json records the source file, sha256 and env steps, so a
fine-tuned policy's total budget is the source's env steps plus the run's.

`--value-warmup N` (PPO) holds the actor and its std fixed as initialised, taken over by --init-from
or fresh, for the first N env steps, so that the first updates train the fresh value function only
(make_value_warmup). A fresh PPO-CPG actor's mean residual is about 0, so a warm-up from scratch
holds the open-loop CPG plus exploration noise while the value function learns what it earns.

A config's `initial_action` (PPO) sets a fresh policy's mean action (set_initial_action).
"""

from __future__ import annotations

from pathlib import Path

from hexbench.artifacts.manifest import MANIFEST_NAME, CheckpointError, read_manifest
from hexbench.training.settings import TrainError


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
