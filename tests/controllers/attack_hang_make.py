"""Attack: make_controller never returns (time.sleep in a loop, swallowing anything raised).

An in-process evaluator has no deadline on make_controller and hangs forever.

An honest evaluator must give make_controller a deadline (`hexbench run --make-timeout SECONDS`;
tests/test_redteam.py passes 5) and then stop the run with one "error: ..." line naming this file,
a non-zero exit, within about 30 s.
"""

import time

import numpy as np


class Never:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    while True:
        try:
            time.sleep(1)
        except BaseException:  # noqa: BLE001 - an in-process timeout exception is swallowed too
            pass
    return Never()
