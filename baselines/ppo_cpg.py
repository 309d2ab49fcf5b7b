"""PPO-CPG (the paper's method): PPO learns a residual a_r on top of the Hopf CPG, a_t = a_c + eps a_r.

    hexbench train baselines/ppo_cpg.py --terrain rough      # train (see hexbench/training/train.py)
    hexbench run baselines/ppo_cpg.py                        # evaluate the shipped weights

Hyper-parameters: paper Table 2. eps is the terrain default of paper 3.2 (0.6 rough, 0.4 slopes,
0.3 stairs). Table 2's "number of epochs 4x10^4" is read as the number of PPO iterations over
the whole run, not SB3's n_epochs (passes over one rollout), which stays at SB3's default of 10.

How each shipped checkpoint was trained is its manifest entry's `command` and `init_from`
(baselines/checkpoints/manifest.json; summary in docs/training.md, "Recipes"). The rough and slopes
weights are warm starts trained with gSDE exploration, e.g. rough:
    --init-from <earlier ppo_cpg-rough.zip> --set use_sde=True --set sde_sample_freq=120 --set log_std_init=-3.5
"""

from dataclasses import dataclass
from pathlib import Path

import torch


@dataclass(frozen=True)
class Config:
    algo: str = "ppo"
    action_mode: str = "cpg_residual"
    residual_scale: float | None = None  # eps; None -> paper 3.2 value of the terrain
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
    use_sde: bool = False  # SB3 default: Gaussian noise drawn anew every step (True: gSDE, docs/training.md)
    sde_sample_freq: int = -1  # SB3 default; with use_sde, steps between new exploration matrices
    log_std_init: float = -2.3  # not in the paper: std 0.10; at 0.37 (-1.0) the deterministic policy decayed (docs/training.md)
    early_end_penalty: bool = True  # not in the paper: ending early must not pay (hexbench.world.rewards)
    normalize_reward: bool = True  # not in the paper: PPO's joint grad-norm clip needs O(1) returns (hexbench.training.train)


CONFIG = Config()
CHECKPOINTS_DIR = Path(__file__).resolve().parent / "checkpoints"


def make_controller(task):
    """The shipped PPO-CPG policy for task.terrain, acting deterministically."""
    from hexbench.agents.policy import make_policy_controller

    torch.set_num_threads(1)
    return make_policy_controller(CONFIG, CHECKPOINTS_DIR, "ppo_cpg", task)
