"""Attack: declare a weights file too large to ever finish hashing.

The evaluator hashes every file a controller lists in `checkpoint_paths` into its record. This
controller lists `huge_weights.bin`, a sparse file of 200 GiB beside it (the test makes it; it takes
no disk space): hashing it would read 200 GiB of zeros, minutes to hours of the evaluator's time
outside every deadline of the controller's. It otherwise walks the open-loop CPG.

An honest evaluator must bound what it reads for a controller: refuse a weights file larger than the
controller process could load at all (its address space) with one "error: ..." line naming this
file, a non-zero exit, within seconds, and never start hashing it.
"""

import numpy as np

WEIGHTS = "huge_weights.bin"  # made beside this file by tests/test_redteam.py (sparse)


class HugeCheckpoint:
    action_mode = "cpg_residual"
    checkpoint_paths = [WEIGHTS]

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return HugeCheckpoint()
