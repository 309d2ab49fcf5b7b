"""SAC-CPG: SAC learns the residual a_r on top of the Hopf CPG, a_t = a_c + eps a_r (paper's 'SAC-CPG').

    hexbench train baselines/sac_cpg.py --terrain rough      # train (see hexbench/training/train.py)
    hexbench run baselines/sac_cpg.py                        # evaluate the shipped weights

Shares PPO-CPG's actor network, learning rate, batch size and gamma (paper Table 2) and eps (paper 3.2);
the critics are [256, 256] and update once every 4 env steps
(1M env steps in hours on one core: docs/training.md); the rest is SB3's SAC defaults apart from a smaller replay buffer.
"""

from dataclasses import dataclass
from pathlib import Path

import torch


@dataclass(frozen=True)
class Config:
    algo: str = "sac"
    action_mode: str = "cpg_residual"
    residual_scale: float | None = None  # eps (cpg_residual only); None -> paper 3.2 value of the terrain
    net_arch: tuple[int, ...] = (256, 256, 256, 256)  # the actor, as PPO (Table 2)
    # the critics: two layers (SB3's default) cost 2.5x less per update than four; the actor acts, the critics only learn
    critic_net_arch: tuple[int, ...] | None = (256, 256)
    activation: str = "relu"  # as PPO (Table 2)
    learning_rate: float = 1e-4  # as PPO (Table 2)
    batch_size: int = 256  # as PPO (Table 2)
    gamma: float = 0.99  # as PPO (Table 2)
    buffer_size: int = 300_000  # transitions; ~0.2 GB, fits next to 5 other jobs on a small machine
    learning_starts: int = 10_000  # random-action steps before the first update
    tau: float = 0.005  # SB3 default (target network soft update)
    train_freq: int = 4  # one update round every 4 env steps (per worker batch): 1M env steps in hours on one core
    gradient_steps: int = 1  # SB3 default: so 0.25 gradient updates per env step (SB3's default is 1)
    ent_coef: str = "auto"  # SB3 default: entropy temperature learned
    log_std_init: float = -1.0  # not in the paper; same initial exploration as the PPO baselines
    action_noise_std: float = 0.0  # SAC explores through its stochastic policy
    early_end_penalty: bool = True  # not in the paper: ending early must not pay (hexbench.world.rewards)


CONFIG = Config()
CHECKPOINTS_DIR = Path(__file__).resolve().parent / "checkpoints"


def make_controller(task):
    """The shipped sac_cpg policy for task.terrain, acting deterministically."""
    from hexbench.agents.policy import make_policy_controller

    torch.set_num_threads(1)
    return make_policy_controller(CONFIG, CHECKPOINTS_DIR, "sac_cpg", task)
