"""Attack: crash the interpreter with a segmentation fault in act() (ctypes.string_at(0)).

In-process the evaluator dies with SIGSEGV: no record, no error message, and the later
controller files on the command line are never run.

An honest evaluator must survive the crash of the controller's process: one "error: ..." line
naming this file (e.g. "killed by signal SIGSEGV"), a non-zero exit, no traceback or core-dump
chatter, and the next controller file on the command line still evaluated.
"""

import ctypes

import numpy as np


class Segfault:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 3:
            ctypes.string_at(0)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Segfault()
