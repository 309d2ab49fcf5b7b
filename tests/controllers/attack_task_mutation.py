"""Attack: mutate the (frozen) TaskSpec handed to make_controller.

make_controller(task) writes through the frozen dataclass with object.__setattr__: the goal
distance becomes 0.01 m and the level 0 (flat ground). In-process that task object is the one the
evaluator then builds its episodes from: every episode is an instant success, and the record is
filed under the real task.

An honest evaluator must give the controller a copy of the task it cannot write back (another
process): the mutation then changes nothing; the run exits 0 with an honest failed score on
stairs 8 cm (or stops with one error line).
"""

import numpy as np


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    for name, value in (("goal_distance_m", 0.01), ("level", 0.0)):
        try:
            object.__setattr__(task, name, value)
        except Exception:  # noqa: BLE001
            pass
    return Honest()
