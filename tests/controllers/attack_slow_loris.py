"""Attack: wait instead of computing, just inside every per-call limit.

Every act() sleeps 9.5 s: no CPU time at all (the limit is 1 s of CPU per call) and less than the
10 s of wall time a call that waits may take. Unchecked, the 1.5 million control steps of the full
protocol would take some 170 days, each step honest.

An honest evaluator must bound the run: the controller's calls may wait about as long as it
computes, and waiting beyond that may reach 60 s in all (hexbench.evaluation.isolation.Limits.wait_budget_s),
so the run stops with one "error: ... waited without computing ..." line naming this file after
some 7 calls, with a non-zero exit.
"""

import time

import numpy as np


class SlowLoris:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        time.sleep(9.5)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return SlowLoris()
