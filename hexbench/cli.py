"""The `hexbench` command line. Core commands live here; feature groups register themselves
from hexbench/commands/<name>.py (see that package's docstring)."""

from __future__ import annotations

import importlib
import pkgutil

import typer

import hexbench.commands

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="hexbench: hexapod locomotion benchmark (run, list, check, train, leaderboard, dataset, ...).")



@app.callback()
def _root() -> None:
    """hexbench: hexapod locomotion benchmark."""


from hexbench.commands import core  # noqa: E402  (the run/list/check commands)

core.register(app)
for _mod in sorted(m.name for m in pkgutil.iter_modules(hexbench.commands.__path__)):
    if _mod != "core":
        importlib.import_module(f"hexbench.commands.{_mod}").register(app)


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # python -m hexbench.cli
    app()
