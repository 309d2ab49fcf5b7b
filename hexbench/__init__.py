"""hexbench: benchmark suite and dataset for hexapod locomotion on challenging terrain."""

__version__ = "0.1.0"

from hexbench.tasks import register_envs as _register_envs  # noqa: E402

_register_envs()
