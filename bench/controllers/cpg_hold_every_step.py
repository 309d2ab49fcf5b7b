"""What baselines/hrl_hold.py starts from, with nothing learned: the CPG's own gait in action mode
cpg_params_steer, its turn set by the heading hold at every control step (hexbench.agents.heading,
as hrl_hold's PolicyController does). A check of the recipe's start, not a baseline:

    hexbench run bench/controllers/cpg_hold_every_step.py --terrain stairs --levels 5,5.5,6,6.5,7 --workers 1 --no-record
"""

from __future__ import annotations

import math

import numpy as np

from hexbench.agents.heading import HeadingHold, with_held_heading
from hexbench.world.env import cpg_params_action

ACTION_MODE = "cpg_params_steer"
HOLD = HeadingHold()  # gain 1, |u| <= 0.3, 1 m look-ahead: hrl_hold's
GAIT = np.asarray(cpg_params_action(math.pi, 0.45, 1.2, 1.0, "cpg_params_wide"))  # the CPG's own gait (paper 2.2)


class HeldCPG:
    action_mode = ACTION_MODE

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return with_held_heading(GAIT, HOLD, obs, ACTION_MODE)


def make_controller(task):
    return HeldCPG()
