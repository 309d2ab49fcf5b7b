"""Attack: answer make_controller with well-formed JSON of the wrong shape.

At import this file wraps the host's send (the `Host` class of the running __main__ module,
hexbench.evaluation.controller_host in a sandbox) so that its reply to MAKE (what the controller declares:
action mode, methods, camera, checkpoint paths) is valid JSON but not an object: `[]`. A
parser that checks only for malformed JSON then calls .get on a list (AttributeError). In-process
there is no host: the attack does nothing and the controller walks the open-loop CPG.

An honest evaluator must validate the shape of every message, not just its syntax: one
"error: ..." line naming this file (a malformed reply), a non-zero exit, never a traceback (or an
honest run, exit 0).
"""

import sys

import numpy as np

try:
    _host = getattr(sys.modules.get("__main__"), "Host", None)
    if _host is not None and callable(getattr(_host, "send", None)):
        _send = _host.send

        def send(self, kind, payload=b""):
            if kind == b"K" and b"action_mode" in payload:
                payload = b"[]"
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
