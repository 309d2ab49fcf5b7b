import time  # noqa: F401

import numpy as np  # noqa: F401


class Broken:
    action_mode = "cpg_residual"

    def __init__(self):
        self.step = 0

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:  # busy for 5 s: over the 1 s of CPU time an act() may use
            end = time.monotonic() + 5
            while time.monotonic() < end:
                pass
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Broken()
