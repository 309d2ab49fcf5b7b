"""Attack: a 200 MB action (np.zeros(50_000_000, dtype=np.float32)) on step 3.

Meant to exhaust the evaluator's message channel or memory when actions cross a process
boundary (a pipe that buffers everything, a decoder that allocates what the sender claims).

An honest evaluator must bound what it reads from the controller's process and stop the run with
one "error: ..." line naming this file and the size or shape problem, a non-zero exit.
"""

import numpy as np


class Huge:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            return np.zeros(50_000_000, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Huge()
