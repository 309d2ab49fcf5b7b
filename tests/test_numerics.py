"""The controller arithmetic of a process (hexbench.suite.numerics)."""

import subprocess
import sys


def test_controller_math_sets_the_environment_without_importing_torch():
    """An evaluation worker whose controllers all run sandboxed never loads torch; torch, once a
    process imports it, still runs on one thread with oneMKL capped."""
    code = ("import os, sys\n"
            "from hexbench.suite.numerics import use_controller_math\n"
            "use_controller_math()\n"
            "assert 'torch' not in sys.modules\n"
            "assert os.environ['MKL_ENABLE_INSTRUCTIONS'] == 'SSE4_2'\n"
            "import torch\n"
            "print(torch.get_num_threads())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False,
                         env={"PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "1"
