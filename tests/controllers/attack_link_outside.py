"""Attack: read a file outside the sandbox's view through a link shipped beside the controller.

A submission is a folder, and the sandbox shows the controller its own folder. This file expects a
link named `outside` beside it that points at a folder the sandbox does not show (the test makes
one holding `secret.txt`; a real attack would point at `/` or a home folder). An evaluator that
follows the submitter's links when it decides what to show would show their targets too. In
reset() the file tries to read `outside/secret.txt`; if it can, it shows the leak by returning an
out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an error.

An honest evaluator must show only its own choice of folders, whatever links they hold: the read
fails, the controller walks the open-loop CPG and the run must exit 0 with an honest failed
score. tests/test_redteam.py runs it with the run folder inside the controller's folder (so that
folder's entries are shown one by one, leaving the run's journal out), under bubblewrap and
under `--isolation process` with Landlock.
"""

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _read_outside() -> bool:
    try:
        return bool((HERE / "outside" / "secret.txt").read_bytes())
    except Exception:  # noqa: BLE001
        return False


class LinkOutside:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.leaked = _read_outside()

    def act(self, obs):
        if self.leaked:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return LinkOutside()
