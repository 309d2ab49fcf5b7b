"""Attack: read the evaluating process's memory, environment and open files through /proc.

A controller process that runs as the evaluator's user (`--isolation process` under a non-root
evaluator) passes the kernel's same-user check on /proc/PID/mem: it could read the evaluator's
state (the run secret, the episode seed, the terrain) and write it (a success flag, the robot's
pose), without the ptrace system call that seccomp forbids. This file looks for the evaluator
(a process whose command line is a `hexbench run`, not itself) and tries to read 16 bytes of
its memory, its environment and where its open files lead. If any succeeds it shows the reach by
returning an out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an error.

An honest evaluator must keep its memory out of the controller's reach (another PID namespace,
another user, or an evaluator that is not dumpable): every read fails, the controller walks the
open-loop CPG and the run must exit 0 with an honest failed score. tests/test_redteam.py runs it
under bubblewrap and under `--isolation process`.
"""

import os
from pathlib import Path

import numpy as np


def _evaluators() -> list[str]:
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            args = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if any(b"hexbench" in a for a in args) and b"run" in args:
            found.append(entry.name)
    return found


def _read_memory(pid: str) -> bool:
    with open(f"/proc/{pid}/maps") as maps:
        start = int(maps.readline().split("-")[0], 16)
    with open(f"/proc/{pid}/mem", "rb") as mem:
        mem.seek(start)
        return len(mem.read(16)) == 16


def _open_files(pid: str) -> bool:
    """Where the evaluator's open files lead (the same check as opening them): the folder may be
    listable (a root controller without capabilities owns it), the links are not."""
    return any(os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd"))


def _reaches_evaluator() -> bool:
    for pid in _evaluators():
        for read in (_read_memory, lambda p: Path(f"/proc/{p}/environ").read_bytes() is not None, _open_files):
            try:
                if read(pid):
                    return True
            except Exception:  # noqa: BLE001 - refused: the next one
                continue
    return False


class EvaluatorMemory:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.reaches = _reaches_evaluator()

    def act(self, obs):
        if self.reaches:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return EvaluatorMemory()
