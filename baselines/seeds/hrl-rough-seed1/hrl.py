"""HRL: PPO chooses the CPG's gait parameters (omega_swing, A1, A2, A3) every control step (paper 4.3).

    hexbench train baselines/hrl.py --terrain rough      # train (see hexbench/training/train.py)
    hexbench run baselines/hrl.py                        # evaluate the shipped weights

Same hyper-parameters as PPO-CPG (paper Table 2); the policy starts at the CPG's own gait (see
initial_action below). The action a in [-1, 1]^4 maps onto
omega_swing in [pi/2, pi] rad/s, A1 in [-1, 1], A2 in [-0.5, 1], A3 in [-1, 0.5] (hexbench.world.env).
"""

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from hexbench.world.env import cpg_params_action


@dataclass(frozen=True)
class Config:
    algo: str = "ppo"
    action_mode: str = "cpg_params"
    residual_scale: float | None = None  # eps (cpg_residual only); None -> paper 3.2 value of the terrain
    net_arch: tuple[int, ...] = (256, 256, 256, 256)  # Table 2, actor and critic alike
    activation: str = "relu"  # Table 2
    learning_rate: float = 1e-4  # Table 2
    batch_size: int = 256  # Table 2 (minibatch size)
    gamma: float = 0.99  # Table 2
    gae_lambda: float = 0.95  # Table 2
    clip_range: float = 0.2  # Table 2
    n_steps: int = 512  # decisions per rollout (30 control steps each)
    n_epochs: int = 10  # SB3 default
    ent_coef: float = 0.0
    log_std_init: float = -1.0  # not in the paper: std 0.37 (SB3's 1.0 saturates most actions)
    early_end_penalty: bool = True  # not in the paper: ending early must not pay (hexbench.world.rewards)
    normalize_reward: bool = True  # not in the paper: PPO's joint grad-norm clip needs O(1) returns (hexbench.training.train)
    # Not in the paper: the policy's mean action starts at the CPG's own gait (omega_swing pi rad/s,
    # A1 0.45; A2 1.2 and A3 1.0 clipped to the ranges' tops, 1.0 and 0.5), which walks every
    # terrain's lowest level. The ranges' midpoint (action 0) has A1 = 0: no hip swing, no walking;
    # started there, HRL made no arrival in 296k steps. PPO-CPG likewise starts at the CPG (a_r = 0).
    initial_action: tuple[float, ...] = cpg_params_action(math.pi, 0.45, 1.2, 1.0)
    # Not in the paper: the policy decides every K control steps (60 Hz) and the CPG keeps its
    # parameters in between (hexbench.training.wrappers.DecisionInterval). 1 = every step, as the
    # shipped v4 weights trained; HRL v4 then switches its hip amplitude bang-bang (docs/training.md).
    decision_interval_steps: int = 30


CONFIG = Config()
CHECKPOINTS_DIR = Path(__file__).resolve().parent / "checkpoints"


def make_controller(task):
    """The shipped hrl policy for task.terrain, acting deterministically."""
    from hexbench.agents.policy import make_policy_controller

    torch.set_num_threads(1)
    return make_policy_controller(CONFIG, CHECKPOINTS_DIR, "hrl", task)
