"""Attack: move off the core the evaluator pinned the controller to, onto another worker's.

`hexbench run` pins each evaluation worker to a core and its controller process inherits the pin,
so that evaluator and controller take turns on one core and workers do not slow each other. In
act() the file asks for every core of the machine (os.sched_setaffinity); before the filter this
worked, and its threads could then take the core of another worker's episodes. If its allowed
cores grow, it makes this visible with an out-of-range action (np.full(18, 5.0)), which any
evaluator rejects with an error; otherwise it walks the open-loop CPG. An honest evaluator must
keep it on its core: the run exits 0 with an honest failed score.
"""

import os

import numpy as np


class LeaveCore:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        pinned = os.sched_getaffinity(0)
        try:
            os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
        except OSError:
            pass
        if len(os.sched_getaffinity(0)) > len(pinned):
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return LeaveCore()
