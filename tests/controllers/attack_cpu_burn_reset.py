"""Attack: reset() busy-loops forever.

An honest evaluator must give reset() the same deadline as act() and stop the run with one
"error: ..." timeout line naming this file, a non-zero exit, within a few seconds.
"""

import numpy as np


class Burn:
    action_mode = "cpg_residual"

    def reset(self, seed):
        while True:
            try:
                while True:
                    pass
            except BaseException:  # noqa: BLE001 - an in-process timeout exception is swallowed too
                pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Burn()
