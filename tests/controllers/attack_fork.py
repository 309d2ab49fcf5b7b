"""Attack: fork in act() and leave the child running.

On step 2 act() forks; the child exec's a Python sleep loop with the marker
"hexbench-attack-marker-fork" in its argv (same session and process group as the controller) and
the parent returns to walking. OSError (fork forbidden) is ignored.

An honest evaluator must end every process the controller started: after the run no process with
the marker may exist. The run exits 0 with an honest failed score, or stops with one error line.
"""

import os
import sys

import numpy as np

MARKER = "hexbench-attack-marker-fork"
LOOP = "import time\nwhile True:\n    time.sleep(1)\n"


class Fork:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 2:
            try:
                pid = os.fork()
            except OSError:
                pid = -1
            if pid == 0:
                try:
                    devnull = os.open(os.devnull, os.O_RDWR)
                    for fd in (0, 1, 2):
                        os.dup2(devnull, fd)
                    os.execv(sys.executable, [sys.executable, "-c", LOOP, MARKER])
                finally:
                    os._exit(0)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Fork()
