"""Attack: an action whose unpickling runs code in the evaluator (pickle __reduce__).

act() returns an np.ndarray subclass holding zeros whose __reduce__ / __reduce_ex__ return
(eval, (EXPR,)): if the evaluator receives actions by unpickling what the controller's process
sends, unpickling evaluates EXPR in the evaluator itself. EXPR writes the evaluator's PID and
command line to /tmp/hexbench-attack-unpickled and yields a valid zero action, so the run would
go on looking normal. In-process (no pickling) the attack does nothing.

An honest evaluator must decode actions as plain numbers (raw float bytes, JSON, a restricted
decoder), never with pickle: /tmp/hexbench-attack-unpickled must not exist after the run, and the
run exits 0 with an honest failed score (or stops with one error line).
"""

import numpy as np

EXPR = ("(open('/tmp/hexbench-attack-unpickled', 'w').write(str(__import__('os').getpid()) + ' ' + "
        "open('/proc/self/cmdline').read().replace(chr(0), ' ')), "
        "__import__('numpy').zeros(18, dtype='float32'))[1]")


class PickleBomb(np.ndarray):
    def __reduce__(self):
        return (eval, (EXPR,))

    def __reduce_ex__(self, protocol):
        return (eval, (EXPR,))


class Controller:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32).view(PickleBomb)


def make_controller(task):
    return Controller()
