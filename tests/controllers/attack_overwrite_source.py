"""Attack: plant code in the evaluator's source tree and in the virtualenv's site-packages.

At import and in make_controller the file tries to create
  * hexbench/hexbench_attack_write.py next to the installed hexbench package (found from
    hexbench.__file__, from the current directory and from /work/main),
  * hexbench_attack_write.pth in every site-packages directory (a .pth file runs its `import`
    lines at every interpreter start: persistent code execution for every later run),
  * and opens hexbench/world/protocol.py for appending (writing nothing: an honest in-process run must
    not be damaged by this test).
Both planted files only hold a comment, so a successful attack does no harm beyond being seen.

An honest evaluator must mount the code it runs read-only for the controller (or not at all):
neither file may exist after the run, and no file of the repository may change. The controller
walks the open-loop CPG, so the run exits 0 with an honest failed score (or one error line).
"""

import os
import site
import sys
from pathlib import Path

import numpy as np

CONTENT = "# planted by tests/controllers/attack_overwrite_source.py (hexbench red-team test)\n"


def _package_dirs():
    dirs = [Path.cwd() / "hexbench", Path("/work/main/hexbench")]
    try:
        import hexbench

        dirs.append(Path(hexbench.__file__).resolve().parent)
    except Exception:  # noqa: BLE001
        pass
    return [d for d in dirs if d.is_dir()]


def _site_dirs():
    dirs = []
    try:
        dirs += site.getsitepackages()
    except Exception:  # noqa: BLE001
        pass
    dirs += [p for p in sys.path if p.endswith("site-packages")]
    return [Path(d) for d in dirs if os.path.isdir(d)]


def _plant() -> None:
    for d in _package_dirs():
        try:
            (d / "hexbench_attack_write.py").write_text(CONTENT)
        except Exception:  # noqa: BLE001
            pass
        try:
            with open(d / "protocol.py", "a"):
                pass
        except Exception:  # noqa: BLE001
            pass
    for d in _site_dirs():
        try:
            (d / "hexbench_attack_write.pth").write_text(CONTENT)
        except Exception:  # noqa: BLE001
            pass


_plant()


class Honest:
    action_mode = "cpg_residual"

    def reset(self, seed):
        pass

    def act(self, obs):
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    _plant()
    return Honest()
