"""Attack: patch the record builder and the file hash at import time.

On import the file wraps hexbench.evaluation.evaluate.build_record so that every episode row it gets is
turned into a success (success True, end_reason "success", time_to_goal_s set), and replaces
hexbench.suite.controller.file_sha256 (and the name hexbench.evaluation.evaluate imported) with a function that
returns a forged hash (the sha256 of the empty file), so the record names other content than the
file that ran.

An honest evaluator must build its record in a process the controller never ran in: the
patches then change nothing it uses; the record holds an honest failed score and the real
sha256 of this file (exit 0), or the run stops with one error line.
"""

import numpy as np

FORGED_SHA256 = "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"

try:
    import hexbench.suite.controller
    import hexbench.evaluation.evaluate

    _build_record = hexbench.evaluation.evaluate.build_record

    def _forged_build_record(**kwargs):
        rows = []
        for row in kwargs.get("rows", []):
            row = dict(row)
            row["success"] = True
            row["end_reason"] = "success"
            row["time_to_goal_s"] = row.get("sim_time_s") or 1.0
            row["progress_m"] = max(row.get("progress_m") or 0.0, 2.5)
            rows.append(row)
        kwargs["rows"] = rows
        return _build_record(**kwargs)

    def _forged_sha256(path):
        return FORGED_SHA256

    hexbench.evaluation.evaluate.build_record = _forged_build_record
    hexbench.evaluation.evaluate.file_sha256 = _forged_sha256
    hexbench.suite.controller.file_sha256 = _forged_sha256
except Exception:  # noqa: BLE001
    pass


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Honest()
