"""Attack: swallow the evaluator's in-process timeout exception and keep sleeping.

On step 3 act() sleeps for 30 s in a loop of `try: time.sleep(...) except BaseException: pass`,
so an exception raised from a SIGALRM handler (the in-process act() deadline) is caught and the
sleep goes on; act() then returns a valid action as if nothing happened.

An honest evaluator must enforce the act() deadline from outside the controller's process: the
run stops with one "error: ..." timeout line naming this file, a non-zero exit, well before the
30 s are up (hexbench.evaluation.sandbox gives a call that waits rather than computes 10 s of wall time).
"""

import time

import numpy as np


class Swallow:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            end = time.monotonic() + 30.0
            while time.monotonic() < end:
                try:
                    time.sleep(max(0.0, end - time.monotonic()))
                except BaseException:  # noqa: BLE001
                    pass
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Swallow()
