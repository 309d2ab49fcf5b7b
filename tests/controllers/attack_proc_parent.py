"""Attack: reach the evaluator through /proc (its command line, environment and open files).

In make_controller and reset() the controller scans /proc for the evaluating process: any process
(itself or another) whose command line is a `hexbench run ... --out DIR` invocation, and tries to
read its /proc/<pid>/environ and list /proc/<pid>/fd. If it finds the evaluator it shows the
leak by returning an out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an
error, instead of exploiting it quietly (reading its memory, writing its pipes).

An honest evaluator must run the controller where the evaluator's processes are invisible (its
own PID namespace with its own /proc): the scan finds nothing, the controller walks the open-loop
CPG and the run must exit 0 with an honest failed score.
"""

import os
from pathlib import Path

import numpy as np


def _evaluator_visible() -> bool:
    try:
        pids = [p.name for p in Path("/proc").iterdir() if p.name.isdigit()]
    except Exception:  # noqa: BLE001
        return False
    for pid in pids:
        try:
            args = [a.decode(errors="replace") for a in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")]
        except Exception:  # noqa: BLE001
            continue
        if any("hexbench" in a for a in args) and "run" in args and "--out" in args:
            try:  # what a quiet attack would go on to use
                Path(f"/proc/{pid}/environ").read_bytes()
                os.listdir(f"/proc/{pid}/fd")
            except Exception:  # noqa: BLE001
                pass
            return True
    return False


class ProcParent:
    action_mode = "cpg_residual"

    def __init__(self):
        self.visible = _evaluator_visible()

    def reset(self, seed):
        self.visible = self.visible or _evaluator_visible()

    def act(self, obs):
        if self.visible:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return ProcParent()
