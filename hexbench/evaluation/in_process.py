"""isolation 'none': the controller object inside the evaluator's own process, for debugging only.

It can reach the simulator and forge its score, so records made this way say so and the
leaderboard refuses them.
"""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np

from hexbench.evaluation.isolation import DEFAULT_LIMITS, Limits
from hexbench.evaluation.remote import NotAnArray, WrongDtype, one_line
from hexbench.suite.controller import CAMERA_EVERY_STEPS, ControllerError
from hexbench.suite.controller import make_controller as make_in_process
from hexbench.suite.numerics import use_controller_math


# ------------------------------------------------------------------------ in-process (debug)
class _CallTimeout(Exception):
    pass


class InProcessController:
    """isolation 'none': the controller object in the evaluator's own process (debugging only)."""

    def __init__(self, controller_file: str, task, limits: Limits = DEFAULT_LIMITS):
        self.file, self.limits = str(controller_file), limits
        use_controller_math()  # in effect where this process has not multiplied matrices yet (a CLI run)
        self.ctrl = make_in_process(controller_file, task)
        self.action_mode = self.ctrl.action_mode
        self.checkpoint_paths = [Path(p).resolve() for p in getattr(self.ctrl, "checkpoint_paths", []) or []]
        camera = getattr(self.ctrl, "camera", None)
        self.camera = camera if camera is not None and callable(getattr(self.ctrl, "see", None)) else None
        if self.camera is not None:
            from hexbench.world.camera import CameraSpec

            if not isinstance(self.camera, CameraSpec):
                raise ControllerError(f"{self.file}: camera is a {type(camera).__name__}; expected hexbench.world.camera.CameraSpec")
        self.camera_every_steps = getattr(self.ctrl, "camera_every_steps", CAMERA_EVERY_STEPS)
        if self.camera is not None and (not isinstance(self.camera_every_steps, int) or self.camera_every_steps < 1):
            raise ControllerError(f"{self.file}: camera_every_steps must be a positive int, got {self.camera_every_steps!r}")

    def _call(self, what: str, context: str, fn, *args):
        def _raise(signum, frame):
            raise _CallTimeout()

        old = signal.signal(signal.SIGALRM, _raise)
        signal.setitimer(signal.ITIMER_REAL, self.limits.call_timeout_s)
        try:
            return fn(*args)
        except _CallTimeout:
            raise ControllerError(f"{self.file}: {what} took longer than {self.limits.call_timeout_s:g} s {context}".rstrip()) from None
        except ControllerError:
            raise
        except BaseException as e:  # noqa: BLE001
            message = one_line(str(e))
            raise ControllerError(f"{self.file}: {what} raised {type(e).__name__} {context}".rstrip()
                                  + (f": {message}" if message else "")) from None
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)

    def reset(self, seed: int) -> None:
        self._call("reset()", "", self.ctrl.reset, seed)

    def see(self, image: np.ndarray, step: int) -> None:
        self._call("see()", f"at step {step}", self.ctrl.see, image)

    def act(self, obs: np.ndarray, step: int):
        action = self._call("act()", f"at step {step}", self.ctrl.act, obs.copy())
        if not isinstance(action, np.ndarray):
            return NotAnArray(type(action).__name__)
        plain = np.ndarray.view(action, np.ndarray)
        if plain.dtype.kind != "f":
            return WrongDtype(str(plain.dtype), plain.shape)
        return plain.copy()
