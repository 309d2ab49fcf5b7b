"""Open-loop CPG baseline: the paper's Hopf-oscillator tripod gait with no learned correction.

In action mode `cpg_residual` the environment adds eps * a_r to the CPG's joint angles
(a_t = a_c + eps a_r, paper eq. 6); this controller always sends a_r = 0, so the robot
executes the CPG output a_c alone (the "CPG" row of paper Table 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Config:
    action_mode: str = "cpg_residual"
    num_joints: int = 18


CONFIG = Config()


class OpenLoopCPG:
    action_mode = CONFIG.action_mode

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros(CONFIG.num_joints, dtype=np.float32)


def make_controller(task) -> OpenLoopCPG:
    return OpenLoopCPG()
