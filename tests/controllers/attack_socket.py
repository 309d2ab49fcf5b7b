"""Attack: talk to the network from the controller (exfiltrate, fetch answers, reach the host).

In make_controller and on the first act() the controller connects to a TCP server on
127.0.0.1:PORT and to the abstract Unix socket "\0hexbench-attack-socket-PORT" and sends a
greeting. PORT = 0 here (the attempt is skipped); tests/test_redteam.py starts its own servers,
copies this file with PORT set to the server's port, and runs the copy. Errors are ignored.

An honest evaluator must give the controller no network (its own network namespace): neither
server may ever accept a connection. The controller walks the open-loop CPG, so the run exits 0
with an honest failed score (or one error line).
"""

import socket

import numpy as np

PORT = 0


def _call() -> None:
    if not PORT:
        return
    try:
        with socket.create_connection(("127.0.0.1", PORT), timeout=1.0) as s:
            s.sendall(b"hexbench-attack-socket tcp\n")
    except Exception:  # noqa: BLE001
        pass
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(1.0)
            s.connect(f"\0hexbench-attack-socket-{PORT}")
            s.sendall(b"hexbench-attack-socket unix\n")
    except Exception:  # noqa: BLE001
        pass


class Socket:
    action_mode = "cpg_residual"

    def __init__(self):
        self.called = False

    def reset(self, seed):
        pass

    def act(self, obs):
        if not self.called:
            self.called = True
            _call()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    _call()
    return Socket()
