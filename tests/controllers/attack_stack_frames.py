"""Attack: walk up the call stack into the evaluator's frames and rewrite its locals.

From act(), the controller walks sys._getframe().f_back upwards. In each frame it looks for the
evaluator's objects: an environment (anything with a `_judge` and a `step`), whose step() it
wraps so that every step reports end_reason "success" and terminated; an `info` dict, whose
end_reason it sets to "success"; and it writes the changed locals back into the frame with
ctypes.pythonapi.PyFrame_LocalsToFast (CPython < 3.13; from 3.13 f_locals writes through).

An honest evaluator must not run the controller on its own stack (another process): the walk
then finds only the controller host's frames, which hold nothing that decides the outcome; the
run gives an honest failed score (exit 0, success False), or stops with one error line.
"""

import sys

import numpy as np


def _forge_env(env) -> None:
    if getattr(env, "_hexbench_attack_forged", False):
        return
    original = env.step

    def forged_step(action):
        obs, reward, terminated, truncated, info = original(action)
        info["end_reason"] = "success"
        info["is_success"] = True
        info["progress_m"] = max(info.get("progress_m", 0.0), 2.6)
        return obs, reward, True, False, info

    env.step = forged_step
    env._hexbench_attack_forged = True


def _walk() -> int:
    touched = 0
    try:
        frame = sys._getframe(1)
    except Exception:  # noqa: BLE001
        return 0
    while frame is not None:
        try:
            local = frame.f_locals
            changed = False
            for key, value in list(local.items()):
                if hasattr(value, "_judge") and callable(getattr(value, "step", None)):
                    _forge_env(value)
                    touched += 1
                if key == "info" and isinstance(value, dict) and "end_reason" in value:
                    value["end_reason"] = "success"
                    changed = True
                if key == "reason" and isinstance(value, (str, type(None))):
                    local[key] = "success"
                    changed = True
            if changed:
                try:
                    import ctypes

                    ctypes.pythonapi.PyFrame_LocalsToFast(ctypes.py_object(frame), ctypes.c_int(0))
                except Exception:  # noqa: BLE001
                    pass
        except Exception:  # noqa: BLE001
            pass
        frame = frame.f_back
    return touched


class StackFrames:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step <= 3:
            _walk()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return StackFrames()
