"""HRL on a held heading: PPO chooses the CPG's gait parameters (omega_swing, A1, A2, A3) every 30
control steps and a fixed heading law steers at every control step (not in the paper; docs/training.md, "HRL").

    hexbench train baselines/hrl_hold.py --terrain rough --seed 1    # train (hexbench/training/train.py)
    hexbench run baselines/hrl_hold.py                               # evaluate the shipped weights

Differences from the paper's HRL (baselines/hrl.py keeps the paper's ranges, baselines/hrl_wide.py
the first difference alone, baselines/hrl_steer.py learns the turn instead):
- the gait ranges of baselines/hrl_wide.py, which contain the CPG's own gait (A2 up to 1.2, A3 up
  to 1.0; the paper's stop at 1.0 and 0.5);
- the turn of action mode cpg_params_steer (the right legs' hip stride (1 + u) times the CPG's, the
  left legs' (1 - u) times) is not learned: the heading hold of the HLTA's low level
  (hexbench.agents.heading.HeadingHold: u proportional to the heading error towards the course's
  centre line 1 m ahead, |u| <= 0.3) sets it from every observation, in training and in evaluation.
  Four symmetric gait parameters cannot steer, and HRL-steer, which learns the turn, learned it in
  some seeds only (baselines/seeds/README.md);
- the policy decides every 30 control steps (0.5 s, a quarter of the CPG's 2 s gait cycle) and
  the CPG keeps its parameters in between; a rollout is 512 decisions;
- the arrival bonus (hexbench.training.wrappers), as baselines/hrl_steer.py; it and the early-end
  penalty are sized for a discount per 30-step decision (end_terms_per_decision, since 2026-12-04).
  Sized per control step, as before, both were 30 times too small, and the policies learned to stop
  0.1-0.5 m short of the goal after 375k-500k env steps while their training return kept rising;
- as baselines/hrl.py: the mean action starts at the CPG's gait (here exactly, to float32), initial
  std 0.37, the early-end penalty and normalised rewards.
Checkpoint selection: held-out episodes (hexbench checkpoints select), as every baseline.
"""

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from hexbench.world.env import cpg_params_action


@dataclass(frozen=True)
class Config:
    algo: str = "ppo"
    action_mode: str = "cpg_params_steer"
    residual_scale: float | None = None  # eps (cpg_residual only)
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
    log_std_init: float = -1.0  # not in the paper: std 0.37
    early_end_penalty: bool = True  # not in the paper: ending early must not pay (hexbench.training.wrappers)
    arrival_bonus: bool = True  # not in the paper: stopping short of the goal must not pay more than arriving
    normalize_reward: bool = True  # not in the paper: PPO's joint grad-norm clip needs O(1) returns
    heading_hold: bool = True  # not in the paper: the turn comes from hexbench.agents.heading.HeadingHold
    # the CPG's own gait (paper 2.2), inside this mode's ranges (those of cpg_params_wide); the turn is the hold's
    initial_action: tuple[float, ...] = cpg_params_action(math.pi, 0.45, 1.2, 1.0, "cpg_params_wide")
    decision_interval_steps: int = 30  # the CPG keeps its parameters for 30 control steps (0.5 s)
    end_terms_per_decision: bool = True  # not in the paper: the end terms bound a discount per decision


CONFIG = Config()
CHECKPOINTS_DIR = Path(__file__).resolve().parent / "checkpoints"


def make_controller(task):
    """The shipped hrl_hold policy for task.terrain, acting deterministically."""
    from hexbench.agents.policy import make_policy_controller

    torch.set_num_threads(1)
    return make_policy_controller(CONFIG, CHECKPOINTS_DIR, "hrl_hold", task)
