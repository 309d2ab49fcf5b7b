"""hexbench: benchmark suite and dataset for hexapod locomotion on challenging terrain."""

from hexbench.artifacts.provenance import HEXBENCH_VERSION
from hexbench.suite.tasks import register_envs as _register_envs

__version__ = HEXBENCH_VERSION

_register_envs()
