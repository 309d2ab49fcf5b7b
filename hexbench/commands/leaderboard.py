"""`hexbench leaderboard build` and `hexbench leaderboard add RUN_DIR` (the package hexbench/leaderboard/)."""

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
        run_dir: Path = typer.Argument(..., help="a run folder written by `hexbench run` (its result.json and "
                                                 "action logs), or a reported record (.json)"),
        directory: Path = typer.Option(Path("leaderboard"), "--dir", help="folder holding the result records"),
        replace: bool = typer.Option(False, "--replace", help="overwrite a record of the same name (never with a "
                                     "less proven one)"),
        protocol: str = typer.Option("v1", help="protocol version of the leaderboard to add to"),
        sample: int = typer.Option(None, "--sample", min=1, help="replay this many episodes drawn at random "
                                   "(default: all; the entry states how many were replayed)"),
        workers: int = typer.Option(0, "--workers", min=0, help="replay processes (0: all cores)"),
        seed_key: str = typer.Option(None, "--seed-key", help="the key of a keyed (hidden) seed set"),
        engine: str = typer.Option("local", "--engine", help="where replays run: local (processes on this machine) "
                                   "or ray (tasks on a Ray cluster; the action logs travel with them)"),
        address: str = typer.Option(None, "--address", help="with --engine ray: the cluster's address HOST:PORT"),
        seed_run: Path = typer.Option(None, "--seed-run", help="admit the run as this seed-run folder's record "
                                      "(baselines/seeds/<method>-<terrain>-seed<S>/result-<terrain>.json) instead"),
        rerun: bool = typer.Option(False, "--rerun", help="play the episodes with the controller the record names "
                                   "instead, sandboxed: every action must be the recorded one and every row the "
                                   "record's, which replays them (the admission says so)"),
        controller: str = typer.Option(None, "--controller", help="with --rerun: the controller file, where it is not "
                                       "at the path the record names (it must be the same file: sha256)"),
    ) -> None:
        """Validate a run's record, replay its episodes from their action logs, copy it in with its admission, rebuild.

        Full runs go to DIR, mixed-course runs to DIR/courses/, paper Table 5's tasks to DIR/courses/table5/."""

        from hexbench.errors import HexbenchError
        from hexbench.evaluation import engines
        from hexbench.leaderboard import RecordError, add, build
        from hexbench.commands.recording import controller_to_rerun
        from hexbench.leaderboard.admission import add_seed_run
        from hexbench.suite.seeds import read_seed_key

        try:
            seed_set = read_seed_key(seed_key) if seed_key else None
            rerun_controller = controller_to_rerun(_record_of(run_dir).get("controller") or {}, controller) if rerun else None
            if rerun_controller is not None and seed_run is not None:
                raise RecordError("--rerun admits a run to the board; a seed run is admitted by replay alone")
            with engines.opened(engine, address) as replay_engine:
                replay_workers = workers or replay_engine.default_workers()
                if seed_run is not None:
                    dest = add_seed_run(run_dir, seed_run, protocol, sample=sample, workers=replay_workers, progress=True)
                else:
                    dest = add(run_dir, directory, replace=replace, protocol=protocol, sample=sample,
                               workers=replay_workers, seed_set=seed_set, progress=True,
                               rerun_controller=rerun_controller)
            result = build(directory, protocol)
        except (RecordError, ValueError, HexbenchError) as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(1) from None
        for line in result.errors:
            typer.echo(f"refused {line}", err=True)
        typer.echo(f"added {dest}; rebuilt {', '.join(str(p) for p in result.written)}")
        if result.errors:
            raise typer.Exit(1)


def _record_of(run_dir: Path) -> dict:
    """The record `leaderboard add` was given: RUN_DIR/result.json, or the record file itself."""
    from hexbench.leaderboard.records import read_record

    return read_record(run_dir / "result.json" if run_dir.is_dir() else run_dir)
