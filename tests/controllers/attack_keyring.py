"""Attack: leave a key in the kernel's keyring, which outlives the controller's process.

In make_controller the file calls add_key for a "user" key in its user keyring. A key stays there
after every process of the run has ended, charged to the user's kernel-memory quota (measured
without a filter: under bubblewrap the key belonged to uid 0 outside the sandbox, and both
isolations left it in /proc/keys after the run). If add_key works, the file invalidates the key at
once (so nothing is left even then) and makes this visible with an out-of-range action
(np.full(18, 5.0)), which any evaluator rejects with an error; otherwise it walks the open-loop
CPG. An honest evaluator must refuse the call: the run exits 0 with an honest failed score.
"""

import ctypes
import ctypes.util

import numpy as np

ADD_KEY, KEYCTL = 248, 250  # x86-64 system call numbers
KEY_SPEC_USER_KEYRING, KEYCTL_INVALIDATE = -4, 21


def _key_added() -> bool:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        key = libc.syscall(ADD_KEY, b"user", b"hexbench-attack-key", b"x" * 100, 100, KEY_SPEC_USER_KEYRING)
    except Exception:  # noqa: BLE001
        return False
    if key < 0:
        return False
    libc.syscall(KEYCTL, KEYCTL_INVALIDATE, key)
    return True


class Keyring:
    action_mode = "cpg_residual"

    def __init__(self, visible: bool):
        self.visible = visible

    def reset(self, seed):
        pass

    def act(self, obs):
        if self.visible:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    import platform

    return Keyring(platform.machine() == "x86_64" and _key_added())
