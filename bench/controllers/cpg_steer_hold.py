"""What the action mode cpg_params_steer can do with nothing learned: the CPG's own gait with a
turn from a proportional heading law (hexbench.agents.heading.HeadingHold, HLTA's), decided every 30
control steps as baselines/hrl_steer.py decides. A check of the mode, not a baseline:

    hexbench run bench/controllers/cpg_steer_hold.py --terrain rough --levels 3,4,11 --workers 1 --no-record
"""

from __future__ import annotations

import math

import numpy as np

from hexbench.agents.heading import HeadingHold
from hexbench.world.env import cpg_params_action

HOLD = HeadingHold(gain=1.0, max_turn=0.3, lookahead_m=1.0)
GAIT = (math.pi, 0.45, 1.2, 1.0)  # the CPG's own gait (paper 2.2): omega_swing [rad/s], A1, A2, A3
DECISION_INTERVAL_STEPS = 30  # as baselines/hrl_steer.py


class SteeredCPG:
    action_mode = "cpg_params_steer"

    def reset(self, seed: int) -> None:
        self.steps = 0
        self.action = np.zeros(5, dtype=np.float32)

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self.steps % DECISION_INTERVAL_STEPS == 0:
            turn = HOLD.turn(obs)
            self.action = np.asarray(cpg_params_action(*GAIT, "cpg_params_steer", turn=turn), dtype=np.float32)
        self.steps += 1
        return self.action


def make_controller(task):
    return SteeredCPG()
