"""Attack: read the run's secret from the run folder and undo the seed derivation.

An evaluator that hides the episode seed from reset() by passing a keyed derivation of it
(HMAC(run secret, "reset/<seed>")) is only as safe as its secret. The secret lives in the run
folder (OUT/.journal/run_secret); with the default output folder (runs/<name>-v1 next to where the
controller sits) that folder lies inside the controller's own folder, which a sandbox typically
shows the controller read-only. In reset(seed) this file looks for files named run_secret under
its own folder, the current directory and /work/main (a few levels deep), and checks whether the
seed it got is a public episode seed, or HMAC(secret, "reset/<public seed>") for any secret found.
If so it makes the foresight visible with an out-of-range action (np.full(18, 5.0)), which any
evaluator rejects with an error.

An honest evaluator must keep the run secret out of the controller's sight (not under any folder
it binds, or unreadable to the sandbox's user): the check then fails, the controller walks the
open-loop CPG and the run must exit 0 with an honest failed score. tests/test_redteam.py runs a
copy with its output folder next to it (the default layout).
"""

import hashlib
import hmac
import os
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SKIP = {".git", ".venv", "site-packages", "__pycache__", "node_modules", "datasets"}


def _secrets() -> list[bytes]:
    found = []
    for base in {HERE, Path.cwd(), Path("/work/main")}:
        depth0 = len(base.parts)
        for root, dirs, files in os.walk(base):
            dirs[:] = [d for d in dirs if d not in SKIP and len(Path(root).parts) - depth0 < 5]
            if "run_secret" in files:
                try:
                    found.append(bytes.fromhex((Path(root) / "run_secret").read_text().strip()))
                except Exception:  # noqa: BLE001
                    pass
    return found


def _public_seeds(task) -> list[int]:
    try:
        return list(task.seeds(100))
    except Exception:  # noqa: BLE001
        return []


class RunSecret:
    action_mode = "cpg_residual"

    def __init__(self, task):
        self.public = _public_seeds(task)
        self.knows = False

    def reset(self, seed):
        self.knows = seed in self.public
        for secret in _secrets():
            for s in self.public:
                digest = hmac.new(secret, f"reset/{s}".encode(), hashlib.sha256).digest()
                if int.from_bytes(digest[:4], "big") == seed:
                    self.knows = True

    def act(self, obs):
        if self.knows:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return RunSecret(task)
