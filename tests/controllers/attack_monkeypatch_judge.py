"""Attack: monkeypatch the episode judge at import time so every episode is a success.

On import the file replaces hexbench.world.protocol.EpisodeJudge (and the name hexbench.world.env imported
from it) with a subclass whose end_reason() says "success" from the third step on, and also
patches the original class's end_reason in place (for judges already built).

An honest evaluator must import the controller file in a process that judges nothing (the
judge runs in the evaluator, which never imports submitted code): the patch then changes only
the controller's own copy, the run gives an honest failed score (exit 0, success False), or it
stops with one error line.
"""

import numpy as np

try:
    import hexbench.world.env
    import hexbench.world.protocol

    _Original = hexbench.world.protocol.EpisodeJudge
    _original_end_reason = _Original.end_reason

    def _forged_end_reason(self, *, step, progress_m, lateral_m, up_z):
        if step >= 3:
            return "success"
        return _original_end_reason(self, step=step, progress_m=progress_m, lateral_m=lateral_m, up_z=up_z)

    class ForgedJudge(_Original):
        end_reason = _forged_end_reason

    hexbench.world.protocol.EpisodeJudge = ForgedJudge
    hexbench.world.env.EpisodeJudge = ForgedJudge
    _Original.end_reason = _forged_end_reason
except Exception:  # noqa: BLE001 - nothing to patch: act honestly
    pass


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Honest()
