"""Attack: declare checkpoint (weights) paths the evaluator chokes on.

The evaluator hashes every file a controller lists in `checkpoint_paths` into its record. This
controller lists "weights\\0.pt" (an embedded NUL byte: most path functions raise ValueError on
it), a path outside its folder (/etc/passwd) and its own folder's parent. It otherwise walks the
open-loop CPG.

An honest evaluator must treat declared paths as untrusted data: refuse them with one "error: ..."
line naming this file (a path that is not a file in the controller's folder), a non-zero exit,
never a traceback; it must never read or hash files outside the controller's folder.
"""

import numpy as np


class BadCheckpoints:
    action_mode = "cpg_residual"
    checkpoint_paths = ["weights\0.pt", "/etc/passwd", ".."]

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return BadCheckpoints()
