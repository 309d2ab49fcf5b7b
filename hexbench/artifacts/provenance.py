"""Where the code comes from: the repository root and the git commit that runs.

Records (`result.json`) and training runs (`run.json`) name the commit; the suite, the shipped
checkpoints and the dataset registry are found from the repository root.
"""

from __future__ import annotations

import os
import platform
import socket
import subprocess
from pathlib import Path

HEXBENCH_VERSION = "0.1.0"  # hexbench.__version__; pyproject.toml carries the same number
PACKAGE_DIR = Path(__file__).resolve().parents[1]  # the hexbench package
REPO_ROOT = PACKAGE_DIR.parent  # the checkout: tasks/, baselines/, datasets/


# Tracked files that are data or prose, not code: result records, the pages built from them, and
# the docs. A change to them alone leaves the commit clean (admitting one record rewrites the
# leaderboard's files, and the next run in that checkout ran the committed code all the same).
NOT_RUN_PATHSPECS: tuple[str, ...] = (":(exclude)leaderboard", ":(exclude)docs", ":(exclude)*.md")


def git_commit(repo: Path | None = None) -> str:
    """HEAD of `repo` (default: the hexbench checkout), `-dirty` when tracked files other than
    NOT_RUN_PATHSPECS changed; "unknown" without git."""
    repo = repo or REPO_ROOT
    try:
        head = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=no",
                                "--", ".", *NOT_RUN_PATHSPECS],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (head + ("-dirty" if dirty else "")) if head else "unknown"


# Packages whose arithmetic an episode's outcome depends on. The physics reproduces bit for bit on
# another x86 machine; a policy's float32 forward pass need not, so records name these versions.
OUTCOME_PACKAGES: tuple[str, ...] = ("numpy", "pybullet", "torch")


def cpu_model() -> str:
    """The processor's model name (/proc/cpuinfo on Linux), else what `platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def package_versions(names: tuple[str, ...] = OUTCOME_PACKAGES) -> dict[str, str | None]:
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str | None] = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


def machine_info() -> dict:
    return {"hostname": socket.gethostname(), "platform": platform.platform(), "python": platform.python_version(),
            "cpu_count": os.cpu_count(), "cpu_model": cpu_model(), "packages": package_versions()}
