"""Attack: a busy loop inside one C call in act(), where no Python signal handler can run.

On step 3 act() evaluates sum(range(10 ** 10)): a single builtin call that runs in C for minutes
and never returns to the interpreter's eval loop, so a SIGALRM handler (the in-process act()
deadline) only runs when it finishes.

An honest evaluator must enforce the act() deadline from outside the controller's process (kill
it): one "error: ..." timeout line naming this file, a non-zero exit, within a few seconds.
"""

import numpy as np


class CBusy:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            sum(range(10 ** 10))
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return CBusy()
