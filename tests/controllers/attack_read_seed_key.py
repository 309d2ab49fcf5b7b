"""Attack: read the secret seed key of a hidden-seed run (`hexbench run FILE --seed-key KEY`).

Hidden seeds are only hidden while the controller cannot read the key: with it, the controller
derives every episode seed as the evaluator does and rebuilds each episode's terrain in advance.
The key's path is on the evaluator's command line, which /proc shows to every process. This file
walks up its ancestors and then through all of /proc for a `--seed-key` argument, resolves it
against that process's working folder, and tries to read the key. If it reads a key it shows the
leak by returning an out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an
error.

An honest evaluator must keep the key out of the controller's sight (covered up in the sandbox),
or refuse to run hidden seeds where it cannot (`--isolation process`, where the controller may
run as a user who can read the key): the run then exits 0 with an honest failed score (the read
fails), or stops with one error line naming `--seed-key` before any episode.
"""

import os
from pathlib import Path

import numpy as np


def _key_paths() -> list[str]:
    pids, pid = [], os.getpid()
    for _ in range(8):  # the ancestors first: the evaluator is one of them
        pids.append(str(pid))
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except Exception:  # noqa: BLE001
            break
        if pid <= 0:
            break
    try:
        pids += [p.name for p in Path("/proc").iterdir() if p.name.isdigit()]
    except OSError:
        pass
    paths = []
    for p in pids:
        try:
            args = Path(f"/proc/{p}/cmdline").read_bytes().split(b"\0")
            if b"--seed-key" in args:
                key = args[args.index(b"--seed-key") + 1].decode()
                paths.append(key if key.startswith("/") else os.path.join(os.readlink(f"/proc/{p}/cwd"), key))
        except Exception:  # noqa: BLE001
            continue
    return paths


def _read_key() -> bytes | None:
    for path in _key_paths():
        try:
            key = Path(path).read_bytes()
        except Exception:  # noqa: BLE001
            continue
        if key:
            return key
    return None


class ReadSeedKey:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.key = _read_key()

    def act(self, obs):
        if self.key:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return ReadSeedKey()
