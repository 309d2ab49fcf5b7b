"""The arithmetic of a process that runs controllers: one thread, and the same bits on every x86-64 CPU.

A learned controller's action is a float32 matrix product (torch, through Intel's oneMKL). oneMKL
picks its kernel by CPU: AVX-512 or AVX2 on Intel processors, an SSE4.2 path on others (AMD), and
each sums in its own order, so the same observation gives actions that differ in the last bits.
The physics amplifies that: the shipped PPO-CPG, played on the same episode seed, succeeded on an
AMD EPYC machine and left the course sideways on an Intel Xeon one. Capping oneMKL at SSE4.2 gives
every x86-64 CPU the kernel that the records made on AMD machines used (checked: the committed
records' golden episodes, `tests/test_golden.py`, reproduce on an AVX-512 Intel Xeon with the cap
and not without). The cost is a slower kernel for the few small products an action needs.

oneMKL reads `MKL_ENABLE_INSTRUCTIONS` at its first call, so it must be in the environment before
the process multiplies anything: in the sandbox's environment, set by evaluation workers before
they import torch, and by held-out checkpoint selection before it plays. It is not set for
training (large batched products would slow down).
"""

from __future__ import annotations

import os
import sys

# Environment of a controller process [variable -> value].
CONTROLLER_MATH_ENV: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_ENABLE_INSTRUCTIONS": "SSE4_2",
}


def use_controller_math() -> None:
    """Give this process (and the processes it starts) the controller arithmetic: call it before
    the process imports torch, or at least before its first matrix product. It does not import
    torch itself: an evaluation worker whose controllers all run sandboxed never needs it (about a
    second of start-up per worker), and torch takes its thread count from this environment when
    it is imported."""
    os.environ.update(CONTROLLER_MATH_ENV)
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)
