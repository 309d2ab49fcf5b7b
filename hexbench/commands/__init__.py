"""CLI command groups. Each module here defines `register(app: typer.Typer)` and is picked up by
hexbench.cli; keep heavy imports (torch, rerun, mcap) inside the command functions."""
