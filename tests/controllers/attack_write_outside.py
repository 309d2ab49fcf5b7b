"""Attack: write files outside any sandbox (temp dir, home, source tree, the run's output).

In make_controller and in act() the controller tries to create a file named
"hexbench-attack-write" in /tmp, in the home directory, in its own folder, in /work/main (the
repository root this project lives in), in the current directory, in every result.json / .journal
folder found by searching upward from os.getcwd() and from its own folder, and in the run's
output folder (read from the --out argument on the command line of this process or any
ancestor it can see under /proc); and it appends a forged line to any result.json and
.journal/*.json it finds there. Every attempt is wrapped so the controller keeps walking.

An honest evaluator must give the controller no writable view of the host's file system (a
private, throw-away /tmp at most): none of those files may exist after the run, no file of the
repository may change, and the run's output holds only what the evaluator wrote. The controller
walks the open-loop CPG, so the run exits 0 with an honest failed score (or one error line).
"""

import os
from pathlib import Path

import numpy as np

NAME = "hexbench-attack-write"
HERE = Path(__file__).resolve().parent


def _cmdlines():
    pid = os.getpid()
    seen = set()
    while pid > 0 and pid not in seen:
        seen.add(pid)
        try:
            yield Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            stat = Path(f"/proc/{pid}/stat").read_text()
            pid = int(stat.rsplit(")", 1)[1].split()[1])
        except Exception:  # noqa: BLE001
            return


def _out_dirs():
    found = []
    for argv in _cmdlines():
        args = [a.decode(errors="replace") for a in argv]
        for i, a in enumerate(args):
            if a == "--out" and i + 1 < len(args):
                found.append(Path(args[i + 1]))
            elif a.startswith("--out="):
                found.append(Path(a.split("=", 1)[1]))
    return found


def _targets():
    dirs = [Path("/tmp"), Path.home(), HERE, Path("/work/main"), Path.cwd()]
    for start in (Path.cwd(), HERE):
        for d in [start, *start.parents]:
            if (d / "result.json").exists() or (d / ".journal").exists():
                dirs.append(d)
                dirs.append(d / ".journal")
    for out in _out_dirs():
        base = out if out.is_absolute() else Path.cwd() / out
        dirs += [base, base / ".journal"]
        try:
            dirs += [p for p in base.iterdir() if p.is_dir()]
            dirs += [p / ".journal" for p in base.iterdir() if p.is_dir()]
        except Exception:  # noqa: BLE001
            pass
    return dirs


def _attack() -> None:
    for d in _targets():
        try:
            (d / NAME).write_text("written by tests/controllers/attack_write_outside.py\n")
        except Exception:  # noqa: BLE001
            pass
        for victim in [d / "result.json", *(d.glob("*.json") if d.name == ".journal" else [])]:
            try:
                if victim.is_file():
                    with open(victim, "a") as f:
                        f.write("\n")  # a visible, harmless change of the evaluator's output
            except Exception:  # noqa: BLE001
                pass


class WriteOutside:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step in (1, 200):
            _attack()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    _attack()
    return WriteOutside()
