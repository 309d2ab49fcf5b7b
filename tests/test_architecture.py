"""The package's layers: the import-linter contracts in pyproject.toml hold (imports point down, no cycles)."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_imports_point_down_the_layers_and_no_package_has_an_import_cycle():
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run([str(lint), "--no-cache"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-1000:]
    assert "Contracts: 2 kept, 0 broken." in result.stdout


def test_the_package_version_is_the_one_pyproject_states():
    import tomllib

    import hexbench

    assert hexbench.__version__ == tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
