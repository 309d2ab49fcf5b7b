import numpy as np

from hexbench.world.camera import CameraSpec


class BlindAfterOneLook:
    action_mode = "cpg_residual"
    camera = CameraSpec(width_px=32, height_px=24)
    camera_every_steps = 3

    def reset(self, seed):
        self.looks = 0

    def see(self, image):
        self.looks += 1
        if self.looks == 2:
            raise OSError("camera unplugged")

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return BlindAfterOneLook()
