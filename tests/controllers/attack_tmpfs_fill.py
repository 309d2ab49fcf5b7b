"""Attack: fill the sandbox's temporary folder (RAM-backed tmpfs) beyond any scratch budget.

In make_controller the file writes 32 MiB files into tempfile.gettempdir(), /tmp and /dev/shm
until 640 MiB is written or a write fails, then deletes them again. On a RAM-backed tmpfs
without a size limit these pages count against neither the address-space limit nor any file-size
limit (each file stays below it): N controllers could take the machine's memory this way. If more
than 512 MiB could be written in one folder, the controller makes this visible with an
out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an error; otherwise it walks the
open-loop CPG. (In-process, on the host's disk, the files are deleted right after.)

An honest evaluator must bound every writable folder of the sandbox (tmpfs --size): the run must
exit 0 with an honest failed score.
"""

import os
import tempfile
from pathlib import Path

import numpy as np

CHUNK = 32 << 20
TOTAL = 640 << 20
LIMIT = 512 << 20


def _fill(folder: Path) -> int:
    written, files = 0, []
    block = b"\0" * CHUNK
    try:
        while written < TOTAL:
            f = folder / f"hexbench-attack-fill-{os.getpid()}-{len(files)}"
            files.append(f)
            with open(f, "wb") as out:
                out.write(block)
            written += CHUNK
    except Exception:  # noqa: BLE001
        pass
    finally:
        for f in files:
            try:
                f.unlink()
            except Exception:  # noqa: BLE001
                pass
    return written


class TmpfsFill:
    action_mode = "cpg_residual"

    def __init__(self, visible: bool):
        self.visible = visible

    def reset(self, seed):
        pass

    def act(self, obs):
        if self.visible:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    most = 0
    for folder in {Path(tempfile.gettempdir()), Path("/tmp"), Path("/dev/shm")}:
        most = max(most, _fill(folder))
    return TmpfsFill(most > LIMIT)
