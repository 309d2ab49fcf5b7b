"""Pure PPO: the policy outputs all 18 joint targets directly (no CPG); paper's 'PPO' baseline.

    hexbench train baselines/ppo.py --terrain rough      # train (see hexbench/training/train.py)
    hexbench run baselines/ppo.py                        # evaluate the shipped weights

Same hyper-parameters as PPO-CPG (paper Table 2); only the action mode differs: a in [-1, 1]^18
maps linearly onto each joint's range. The paper reports that pure DRL fails on these terrains.
"""

from dataclasses import dataclass
from pathlib import Path

import torch


@dataclass(frozen=True)
class Config:
    algo: str = "ppo"
    action_mode: str = "joint"
    residual_scale: float | None = None  # eps (cpg_residual only); None -> paper 3.2 value of the terrain
    net_arch: tuple[int, ...] = (256, 256, 256, 256)  # Table 2, actor and critic alike
    activation: str = "relu"  # Table 2
    learning_rate: float = 1e-4  # Table 2
    batch_size: int = 256  # Table 2 (minibatch size)
    gamma: float = 0.99  # Table 2
    gae_lambda: float = 0.95  # Table 2
    clip_range: float = 0.2  # Table 2
    n_steps: int = 2048  # rollout length per env (SB3 default)
    n_epochs: int = 10  # SB3 default
    ent_coef: float = 0.0
    log_std_init: float = -1.0  # not in the paper: std 0.37 (SB3's 1.0 saturates most actions)
    early_end_penalty: bool = True  # not in the paper: ending early must not pay (hexbench.world.rewards)
    normalize_reward: bool = True  # not in the paper: PPO's joint grad-norm clip needs O(1) returns (hexbench.training.train)


CONFIG = Config()
CHECKPOINTS_DIR = Path(__file__).resolve().parent / "checkpoints"


def make_controller(task):
    """The shipped ppo policy for task.terrain, acting deterministically."""
    from hexbench.agents.policy import make_policy_controller

    torch.set_num_threads(1)
    return make_policy_controller(CONFIG, CHECKPOINTS_DIR, "ppo", task)
