"""Attack: os._exit(0) in act(): end the evaluating process with a success status.

On step 3 act() calls os._exit(0). In-process that ends the whole `hexbench run` with exit status
0 and no record, and every later controller file on the command line is silently skipped.

An honest evaluator must see the controller's process vanish and report it: one "error: ..."
line naming this file, a non-zero exit, no record for it, and every other controller file given
on the same command line still evaluated (tests/test_redteam.py runs it before baselines/cpg.py).
"""

import os

import numpy as np


class OsExit:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            os._exit(0)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return OsExit()
