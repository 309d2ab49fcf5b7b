"""Attack: a user namespace of its own, and in it a tmpfs of any size (RAM no limit counts).

In make_controller the file calls unshare(CLONE_NEWUSER | CLONE_NEWNS), maps its user, mounts a
tmpfs with size=8g on a folder of its scratch folder and writes up to 320 MiB into it, then deletes
the files. Without a filter this worked under bubblewrap (600 MiB written), where the sandbox's
own tmpfs folders are sized: a tmpfs's pages count against no address-space or file-size limit
beyond each file's. If more than 256 MiB could be written there, the controller makes this
visible with an out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an
error; otherwise it walks the open-loop CPG. An honest evaluator must refuse the namespace or the
mount: the run exits 0 with an honest failed score.
"""

import ctypes
import ctypes.util
import os

import numpy as np

CLONE_NEWUSER, CLONE_NEWNS = 0x10000000, 0x00020000
CHUNK = 32 << 20
TOTAL = 320 << 20
LIMIT = 256 << 20


def _tmpfs_bytes() -> int:
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    uid, gid = os.getuid(), os.getgid()
    if libc.unshare(CLONE_NEWUSER | CLONE_NEWNS) != 0:
        return 0
    for name, text in (("setgroups", "deny"), ("uid_map", f"0 {uid} 1"), ("gid_map", f"0 {gid} 1")):
        try:
            with open(f"/proc/self/{name}", "w") as f:
                f.write(text)
        except OSError:
            pass
    os.makedirs("hexbench-attack-mount", exist_ok=True)
    if libc.mount(b"none", b"hexbench-attack-mount", b"tmpfs", 0, b"size=8g") != 0:
        return 0
    written, files = 0, []
    try:
        while written < TOTAL:
            path = f"hexbench-attack-mount/{len(files)}"
            files.append(path)
            with open(path, "wb") as out:
                out.write(bytes(CHUNK))
            written += CHUNK
    except OSError:
        pass
    finally:
        for path in files:
            try:
                os.remove(path)
            except OSError:
                pass
    return written


class NamespaceTmpfs:
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
    return NamespaceTmpfs(_tmpfs_bytes() > LIMIT)
