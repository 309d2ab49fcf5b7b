"""Attack: answer act() with a message the evaluator's JSON parser cannot survive (deep nesting).

Everything in the controller's process is the controller's to change, the sandbox's own host code
included. At import this file wraps the host's send (the `Host` class of the running __main__
module, hexbench.evaluation.controller_host in a sandbox) so that every ACTION message it sends carries, as
its JSON header line, 2,000 nested arrays ("[[[[...]]]]", 4 kB): a parser with a recursion limit
raises RecursionError, which is not a ValueError. In-process there is no host: the attack does
nothing and the controller walks the open-loop CPG.

An honest evaluator must turn any bytes the controller's process sends into either a valid action
or one "error: ..." line naming this file (a malformed message); never a traceback.
"""

import sys

import numpy as np

DEPTH = 2000

try:
    _host = getattr(sys.modules.get("__main__"), "Host", None)
    if _host is not None and callable(getattr(_host, "send", None)):
        _send = _host.send

        def send(self, kind, payload=b""):
            if kind == b"a":
                payload = b"[" * DEPTH + b"]" * DEPTH + b"\n" + bytes(72)
            return _send(self, kind, payload)

        _host.send = send
except Exception:  # noqa: BLE001
    pass


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Honest()
