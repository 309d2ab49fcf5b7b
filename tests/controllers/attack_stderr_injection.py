"""Attack: inject terminal control sequences into the evaluator's error line via stderr.

At import the file prints to stderr a line that starts with ANSI escape sequences (erase line,
carriage return, green colour) followed by a fake verdict ("hexbench-attack-injected: 20/20
episodes succeeded"), then ends its process with os._exit(3). An evaluator that quotes the
controller's last stderr line in its start-up error passes the escapes to the user's terminal,
which then shows the fake verdict in place of the error.

An honest evaluator must report the failure in one "error: ..." line naming this file, with any
text it quotes from the controller stripped of control characters (the test checks that stderr
holds no control character but newlines and tabs), and a non-zero exit.
"""

import os
import sys

import numpy as np

sys.stderr.write("\x1b[2K\r\x1b[32mhexbench-attack-injected: 20/20 episodes succeeded\x1b[0m\x07\n")
sys.stderr.flush()
os._exit(3)


class Honest:  # never reached
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Honest()
