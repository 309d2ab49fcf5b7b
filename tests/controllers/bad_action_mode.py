import numpy as np


class Broken:
    action_mode = "torque"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Broken()
