"""Attack: a thread that keeps running between and after act() calls.

make_controller starts a non-daemon thread that never ends. While the episode runs it keeps
looking (gc.get_objects) for the evaluator's HexapodEnv and, when it finds one, moves its
recorded start 3 m back (a forged success decided while no controller code is "running"). After
the run, a non-daemon thread also keeps an in-process interpreter from exiting: the command hangs.

An honest evaluator must end the controller's process (threads and all) when the run is over and
must not share memory with it: the run exits 0 with an honest failed score (or one error line),
and it ends promptly.
"""

import gc
import threading
import time

import numpy as np


def _loop() -> None:
    forged = set()
    while True:
        try:
            for obj in gc.get_objects():
                if type(obj).__name__ == "HexapodEnv" and id(obj) not in forged and hasattr(obj, "_start_x"):
                    obj._start_x -= 3.0
                    forged.add(id(obj))
        except Exception:  # noqa: BLE001
            pass
        time.sleep(0.2)


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    threading.Thread(target=_loop, daemon=False, name="hexbench-attack-thread").start()
    return Honest()
