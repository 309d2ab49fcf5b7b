"""Attack: disarm the evaluator's SIGALRM deadline, then busy-loop for 30 s in act().

On step 3 act() sets signal.signal(SIGALRM, SIG_IGN) and setitimer(ITIMER_REAL, 0) (both only
work in the main thread; failures are ignored), then spins for 30 s and returns a valid action.

An honest evaluator must time act() from outside the controller's process: the run stops with one
"error: ..." timeout line naming this file, a non-zero exit, within a few seconds.
"""

import signal
import time

import numpy as np


class IgnoreAlarm:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            try:
                signal.signal(signal.SIGALRM, signal.SIG_IGN)
                signal.setitimer(signal.ITIMER_REAL, 0)
            except Exception:  # noqa: BLE001
                pass
            end = time.monotonic() + 30.0
            while time.monotonic() < end:
                pass
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return IgnoreAlarm()
