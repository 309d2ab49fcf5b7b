"""`hexbench leaderboard build` and `hexbench leaderboard add RESULT.json` (see hexbench/leaderboard.py)."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    group = typer.Typer(no_args_is_help=True, add_completion=False,
                        help="Build the leaderboard from result records, or add a validated record to it.")
    app.add_typer(group, name="leaderboard")

    @group.command("build")
    def build_cmd(
        directory: Path = typer.Option(Path("leaderboard"), "--dir", help="folder holding the result records"),
        protocol: str = typer.Option("v1", help="protocol version to show (records of others are never mixed in)"),
    ) -> None:
        """Validate every record in --dir and write README.md, index.html and leaderboard.csv there."""
        from rich.console import Console

        from hexbench.leaderboard import RecordError, build

        console = Console()
        try:
            with console.status(f"building the {protocol} leaderboard from {directory}/*.json"):
                result = build(directory, protocol)
        except (RecordError, ValueError) as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(1) from None
        for line in result.skipped:
            typer.echo(f"skipped {line}", err=True)
        for line in result.errors:
            typer.echo(f"refused {line}", err=True)
        board = result.board
        typer.echo(f"{len(board.measured)} measured entries, {len(board.reported)} paper reference series "
                   f"-> {', '.join(str(p) for p in result.written)}")
        if result.errors:
            raise typer.Exit(1)

    @group.command("add")
    def add_cmd(
        result_json: Path = typer.Argument(..., help="result record written by `hexbench run`"),
        directory: Path = typer.Option(Path("leaderboard"), "--dir", help="folder holding the result records"),
        replace: bool = typer.Option(False, "--replace", help="overwrite a record of the same name"),
        protocol: str = typer.Option("v1", help="protocol version of the leaderboard to add to"),
    ) -> None:
        """Validate RESULT.json (protocol, every seed, provenance, summary vs episodes), copy it in, rebuild."""
        from hexbench.leaderboard import RecordError, add, build

        try:
            dest = add(result_json, directory, replace=replace, protocol=protocol)
            result = build(directory, protocol)
        except (RecordError, ValueError) as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(1) from None
        for line in result.errors:
            typer.echo(f"refused {line}", err=True)
        typer.echo(f"added {dest}; rebuilt {', '.join(str(p) for p in result.written)}")
        if result.errors:
            raise typer.Exit(1)
