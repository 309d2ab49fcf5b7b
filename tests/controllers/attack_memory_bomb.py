"""Attack: allocate (and touch) 9 GB in act(), starving the machine.

On step 3 act() asks for np.ones(9 << 30, dtype=np.uint8) (every page written) and keeps it.

An honest evaluator must cap the controller's memory (an address-space / cgroup limit): the
allocation fails (MemoryError, or the child is killed) and the run stops with one error line, or,
if the allocation is refused and the controller goes on, the run exits 0 with an honest failed
score. It must never hold the machine's memory or print a traceback.
"""

import numpy as np


class MemoryBomb:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0
        self.hog = None

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            self.hog = np.ones(9 << 30, dtype=np.uint8)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return MemoryBomb()
