"""The `hexbench` command line. Core commands live here; feature groups register themselves
from hexbench/commands/<name>.py (see that package's docstring).

Every user-facing failure is a `hexbench.errors.HexbenchError`; one that a command does not
handle itself ends the command with `error: <message>` on stderr and exit status 1.
"""

from __future__ import annotations

import importlib
import pkgutil

import typer
from typer.core import TyperGroup

import hexbench.commands
from hexbench.errors import HexbenchError


def error_line(error: BaseException) -> str:
    """An error's message as one line (its first line; the class name if it has no message)."""
    lines = str(error).strip().splitlines()
    return lines[0] if lines else type(error).__name__


class HexbenchGroup(TyperGroup):
    """The root command group: a HexbenchError from any command becomes one `error:` line and exit 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except HexbenchError as e:
            typer.echo(f"error: {error_line(e)}", err=True)
            raise typer.Exit(1) from None


app = typer.Typer(cls=HexbenchGroup, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="hexbench: hexapod locomotion benchmark (run, list, check, train, leaderboard, dataset, ...).")


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"hexbench {hexbench.__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                       help="print the hexbench version and exit")) -> None:
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
