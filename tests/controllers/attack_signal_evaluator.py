"""Attack: reach the evaluating process by its pid: signals, resource limits, pidfds.

A controller process that runs as the evaluator's user (`--isolation process` under a non-root
evaluator, or root where `nobody` cannot read the Python environment) could stop the evaluator
(SIGSTOP: the run hangs for good), kill it (exit 137, no line, no record), kill every process of
its user (kill(-1, ...)), or give it a file-size limit of 0 (prlimit: it dies writing its record).
This file only probes, with signal 0 and a read of the limits, which change nothing: each probe
that the kernel allows shows the reach by returning an out-of-range action (np.full(18, 5.0)),
which any evaluator rejects with an error. It probes its parent, its parent's process group,
every process (-1), and the parent through a pidfd.

An honest evaluator must keep signals and limits to the controller's own process (seccomp, or
another PID namespace): every probe fails, the controller walks the open-loop CPG and the run
must exit 0 with an honest failed score. tests/test_redteam.py runs it under bubblewrap and under
`--isolation process`.
"""

import os
import resource
import signal

import numpy as np


def _reaches_another_process() -> bool:
    parent = os.getppid()
    probes = [lambda: os.kill(parent, 0), lambda: os.kill(-1, 0),
              lambda: os.killpg(os.getpgid(parent), 0),
              lambda: resource.prlimit(parent, resource.RLIMIT_FSIZE),
              lambda: signal.pidfd_send_signal(os.pidfd_open(parent), 0)]
    for probe in probes:
        try:
            probe()
            return True
        except Exception:  # noqa: BLE001 - refused: the next one
            continue
    return False


class SignalEvaluator:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.reaches = _reaches_another_process()

    def act(self, obs):
        if self.reaches:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return SignalEvaluator()
