"""Core commands: `hexbench run`, `hexbench list`, `hexbench check`."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    @app.command("list")
    def list_tasks(protocol: str = typer.Option("v1", help="protocol version")) -> None:
        """List terrains, levels and Gymnasium task ids."""
        from rich.console import Console
        from rich.table import Table

        from hexbench.tasks import format_level, load_suite, registered_ids

        suite = load_suite(protocol)
        table = Table(title=f"hexbench protocol {protocol}")
        for col in ("terrain", "unit", "paper levels (Table 4)", "headroom levels"):
            table.add_column(col)
        for terrain in suite.terrains:
            tasks = [t for t in suite.tasks if t.terrain == terrain]
            table.add_row(terrain, tasks[0].unit,
                          ", ".join(format_level(t.level) for t in tasks if not t.headroom),
                          ", ".join(format_level(t.level) for t in tasks if t.headroom))
        console = Console()
        console.print(table)
        ids = registered_ids()
        console.print(f"{len(ids)} Gymnasium ids registered, e.g. {ids[0]} ... {ids[-1]}")
