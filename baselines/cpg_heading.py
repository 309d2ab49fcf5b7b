"""The open-loop CPG held on its heading: a_r steers, nothing is learned (an ablation of HLTA's low level).

    hexbench run baselines/cpg_heading.py --terrain mixed    # the mixed course (leaderboard/courses/)

The CPG's tripod gait (baselines/cpg.py) plus the heading hold of hexbench.agents.heading: the residual
touches only the hips, scaling the right legs' stride by (1 + u) and the left legs' by (1 - u), with u a
proportional law on the heading error towards the centre line 1 m ahead, |u| <= 0.3. It is what
baselines/hlta.py dispatches on rough ground and slopes; scored on its own it shows how much of the
hierarchy's result on the mixed course the heading hold gives and how much the classifier and the
stairs policy add.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexbench.agents.heading import HeadingHold, HeadingSteering

HEADING_HOLD = HeadingHold(gain=1.0, max_turn=0.3, lookahead_m=1.0)  # as baselines/hlta.py


@dataclass(frozen=True)
class Config:
    action_mode: str = "cpg_residual"
    heading_hold: HeadingHold = HEADING_HOLD


CONFIG = Config()


class HeadingHeldCPG:
    action_mode = CONFIG.action_mode

    def __init__(self, steering: HeadingSteering):
        self.steering = steering

    def reset(self, seed: int) -> None:
        self.steering.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.clip(self.steering.residual(obs), -1.0, 1.0).astype(np.float32)


def make_controller(task) -> HeadingHeldCPG:
    return HeadingHeldCPG(HeadingSteering.for_task(CONFIG.heading_hold, task))
