"""Attack: write garbage to stdout, stderr and every pipe or socket it has open.

On the first act() the controller prints a fake success table and a fake traceback (both holding
the text "hexbench-attack-output") to stdout and stderr, and writes a forged message (a JSON line
and raw bytes) to every file descriptor 3..255 that is a pipe or a socket: if the evaluator talks
to the controller's process over such a channel, the stream is now corrupt. It keeps walking.

An honest evaluator must keep its own output and its message channel out of the controller's
reach (or frame and validate every message): the run's stdout/stderr hold none of the controller's
text, and the run exits 0 with an honest failed score, or stops with one "error: ..." line.
"""

import os
import stat
import sys

import numpy as np

FAKE = ("hexbench-attack-output\n"
        "| 8 | 100% | 80-100% | 1/1 | 0.200 | 0.01 |\n"
        "Traceback (most recent call last):\n  File \"hexbench-attack-output\", line 1\n"
        "error: hexbench-attack-output\n")
FORGED = (b'{"type": "action", "success": true, "end_reason": "success", "hexbench-attack-output": 1}\n'
          b"\x00\xff\x7f\x00garbage hexbench-attack-output\n" * 4)


def _garbage() -> None:
    try:
        print(FAKE, flush=True)
        print(FAKE, file=sys.stderr, flush=True)
    except Exception:  # noqa: BLE001
        pass
    for fd in (1, 2):
        try:
            os.write(fd, FAKE.encode())
        except Exception:  # noqa: BLE001
            pass
    for fd in range(3, 256):
        try:
            mode = os.fstat(fd).st_mode
        except OSError:
            continue
        if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
            try:
                os.set_blocking(fd, False)
                os.write(fd, FORGED)
            except Exception:  # noqa: BLE001
                pass


class Garbage:
    action_mode = "cpg_residual"

    def __init__(self):
        self.done = False

    def reset(self, seed):
        pass

    def act(self, obs):
        if not self.done:
            self.done = True
            _garbage()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Garbage()
