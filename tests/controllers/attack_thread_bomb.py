"""Attack: start threads until the machine has no process ids left.

Each act() starts 200 more threads (64 KiB stacks, each waiting on an event), up to 4,000. No
rlimit stops this (RLIMIT_NPROC does not apply to a user namespace's root, the address-space limit
allows tens of thousands of small stacks, and each act() stays within its CPU time): 3,000 threads
took 0.33 s to start, and a 2-core VM's pid_max is 32,768, which every thread of the machine
shares, so a few seconds of this leave the evaluator and everything else unable to start a thread
or a process.

An honest evaluator must bound the controller's threads: the run stops with one error line naming
the threads, and nothing of the controller is left.
"""

import threading

import numpy as np

PER_CALL = 200
MOST = 4000


class ThreadBomb:
    action_mode = "cpg_residual"

    def __init__(self):
        self.stop = threading.Event()
        self.started = 0

    def reset(self, seed):
        pass

    def act(self, obs):
        if self.started < MOST:
            threading.stack_size(64 << 10)
            for _ in range(PER_CALL):
                threading.Thread(target=self.stop.wait, daemon=True).start()
            self.started += PER_CALL
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return ThreadBomb()
