"""Evaluation worker processes: one per core, pinned, with a watchdog that ends them with their evaluator.

Each worker and the controller processes it starts share one core: they never run at once, and a
round trip between them on one core costs a few microseconds instead of tens across cores.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from hexbench.evaluation import isolation, sandbox
from hexbench.suite.numerics import use_controller_math


def exit_when_orphaned(parent_pid: int, poll_s: float = 1.0) -> None:
    """Worker-side watchdog: exit as soon as the evaluating process is gone (killed by SIGTERM or
    SIGKILL, it cannot shut its pool down; without this its spawn workers would wait forever)."""
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(1)


def worker_init(parent_pid: int, next_core=None, hide_from_controllers: bool = False) -> None:
    """A pool worker's set-up: the orphan watchdog, the controller processes' clean-up, the
    controllers' math, its core; and (`hide_from_controllers`, for process-isolated controllers)
    not dumpable before any controller of any worker starts."""
    import threading
    from multiprocessing import util

    if hide_from_controllers:
        isolation.hide_from_controllers()
    threading.Thread(target=exit_when_orphaned, args=(parent_pid,), daemon=True, name="orphan-watchdog").start()
    util.Finalize(None, sandbox.close_all, exitpriority=10)
    use_controller_math()  # for in-process controllers here; sandboxed ones get it in their clean environment
    if next_core is not None:
        with next_core.get_lock():
            slot = next_core.value
            next_core.value += 1
        pin_to_core(slot)


def pin_to_core(slot: int | None = None) -> set[int] | None:
    """Pin this process (and the controller processes it starts) to one core of its allowed set:
    the `slot`-th, or (None) the one it runs on now, so that single-worker runs started side by
    side do not pile onto one core. Returns the previous set. Evaluator and controller then share
    a core: they never run at once, and a round trip on one core costs a few microseconds instead
    of tens across cores."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    core = allowed[slot % len(allowed)] if slot is not None else _current_cpu(allowed)
    os.sched_setaffinity(0, {core})
    return set(allowed)


def _current_cpu(allowed: list[int]) -> int:
    """The CPU this process last ran on (/proc/self/stat field 39), if it is allowed."""
    try:
        cpu = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[36])
    except (OSError, ValueError, IndexError):
        return allowed[0]
    return cpu if cpu in allowed else allowed[0]
