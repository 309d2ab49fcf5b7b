"""The commit a record names: `-dirty` only when a file that runs differs from it."""

import shutil
import subprocess
from pathlib import Path

import pytest

from hexbench.artifacts.provenance import git_commit

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True, text=True).stdout.strip()


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    for name, text in {"hexbench/sim.py": "STEP = 1\n", "leaderboard/ppo.json": "{}\n", "leaderboard/README.md": "# board\n",
                       "docs/trust.md": "# trust\n", "README.md": "# hexbench\n"}.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", "-A")
    _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "start")
    return tmp_path


def test_a_clean_checkout_names_its_head(checkout: Path):
    assert git_commit(checkout) == _git(checkout, "rev-parse", "HEAD")


@pytest.mark.parametrize("edited", ["leaderboard/ppo.json", "leaderboard/README.md", "docs/trust.md", "README.md"])
def test_records_pages_and_prose_changed_since_the_commit_leave_it_clean(checkout: Path, edited: str):
    (checkout / edited).write_text("changed by an admission\n")
    assert git_commit(checkout) == _git(checkout, "rev-parse", "HEAD")


def test_code_changed_since_the_commit_is_dirty(checkout: Path):
    (checkout / "leaderboard/ppo.json").write_text("changed\n")
    (checkout / "hexbench/sim.py").write_text("STEP = 2\n")
    assert git_commit(checkout) == _git(checkout, "rev-parse", "HEAD") + "-dirty"


def test_outside_a_git_checkout_the_commit_is_unknown(tmp_path: Path):
    assert git_commit(tmp_path / "nowhere") == "unknown"
