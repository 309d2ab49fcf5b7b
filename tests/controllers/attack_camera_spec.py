"""Attack: a camera whose parameters make the evaluator's renderer hang (fov_deg = 1e-6).

A seeing controller (hexbench.suite.controller.SeeingController) declares the body-mounted camera it
wants; the evaluator renders the image itself (PyBullet's TinyRenderer) and sends it. This file
declares a CameraSpec with a field of view of 1e-6 degrees: every finite number and the pixel count
pass a plain sanity check, but TinyRenderer then takes minutes (or forever) on the first image,
inside the evaluator's own process, where no act() deadline applies. see() and act() are honest.

An honest evaluator must bound the camera parameters it accepts (a sensible fov, near/far and
mount range) or render under a deadline of its own: one "error: ..." line naming this file, or an
honest run (exit 0, success False), within 20 s.
"""

import numpy as np

from hexbench.world.camera import CameraSpec


class Seeing:
    action_mode = "cpg_residual"
    camera = CameraSpec(fov_deg=1e-6)

    def reset(self, seed):
        pass

    def see(self, image):
        return None

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Seeing()
