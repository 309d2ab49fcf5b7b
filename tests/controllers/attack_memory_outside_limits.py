"""Attack: hold memory that no address-space limit counts (memfds, SysV shared memory).

A memfd's pages, and a SysV segment's once detached, belong to the kernel, not to the process's
address space: with 256 open files of 64 MiB, memfds alone hold 16 GiB past a 4 GiB limit (measured
without a filter: 80 memfds of 60 MiB held 4.7 GB of the machine's memory). A SysV segment also
outlives its process where there is no IPC namespace, and any process of the same user can attach
it by id.

In make_controller the file tries memfd_create (writing up to 320 MiB into memfds, then closing
them) and shmget (removing a segment it gets at once). If either call works, it makes this
visible with an out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an error;
otherwise it walks the open-loop CPG. An honest evaluator must refuse both calls: the run exits 0
with an honest failed score.
"""

import ctypes
import ctypes.util
import os

import numpy as np

CHUNK = 32 << 20
TOTAL = 320 << 20
IPC_PRIVATE, IPC_CREAT, IPC_RMID = 0, 0o1000, 0


def _memfd_bytes() -> int:
    written, fds = 0, []
    try:
        while written < TOTAL:
            fd = os.memfd_create("hexbench-attack-memfd")
            fds.append(fd)
            os.write(fd, bytes(CHUNK))
            written += CHUNK
    except Exception:  # noqa: BLE001
        pass
    finally:
        for fd in fds:
            os.close(fd)
    return written


def _sysv_segment() -> bool:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        segment = libc.shmget(IPC_PRIVATE, CHUNK, IPC_CREAT | 0o600)
    except Exception:  # noqa: BLE001
        return False
    if segment < 0:
        return False
    libc.shmctl(segment, IPC_RMID, None)
    return True


class OutsideLimits:
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
    return OutsideLimits(_memfd_bytes() > 0 or _sysv_segment())
