"""Core commands: `hexbench run`, `hexbench list`, `hexbench check`."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    _register_run(app)

    @app.command("list")
    def list_tasks(protocol: str = typer.Option("v1", help="protocol version"),
                   ids: bool = typer.Option(False, "--ids", help="print only the Gymnasium ids, one per line")) -> None:
        """List terrains, levels and Gymnasium task ids."""
        from hexbench.suite.tasks import format_level, load_suite, registered_ids

        try:
            suite = load_suite(protocol)
        except ValueError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2)
        protocol_ids = [gid for gid in registered_ids() if gid.endswith(f"-{protocol}")]  # registered on import
        if ids:
            for gid in protocol_ids:
                typer.echo(gid)
            return
        from rich.console import Console
        from rich.table import Table

        table = Table(title=f"hexbench protocol {protocol}")
        for col in ("terrain", "unit", "paper levels (Table 4)", "headroom levels"):
            table.add_column(col)
        for terrain in suite.all_terrains:
            tasks = [t for t in suite.all_tasks if t.terrain == terrain]
            name = terrain if tasks[0].in_full_run else f"{terrain} (extra course: --terrain {terrain})"
            table.add_row(name, tasks[0].unit or "level",
                          ", ".join(format_level(t.level) for t in tasks if not t.headroom),
                          ", ".join(format_level(t.level) for t in tasks if t.headroom))
        console = Console()
        console.print(table)
        console.print(f"{len(protocol_ids)} Gymnasium ids registered (--ids lists them), e.g. "
                      f"{suite.tasks[0].gym_id('cpg_residual')}", highlight=False, soft_wrap=True)


def _parse_levels(text: str | None) -> list[float] | None:
    if not text:
        return None
    try:
        return [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise ValueError(f"--levels must be comma-separated numbers in the paper's units (cm, deg), got {text!r}") \
            from None


def print_success_table(record: dict, console) -> None:
    """Per-terrain success rates (paper Table 4's content, one row per level so it fits any
    terminal), with 95% Wilson intervals, then the terrain summary."""
    from rich.table import Table

    from hexbench.suite.tasks import format_level

    for terrain in record["terrains"]:
        name = terrain["terrain"]
        table = Table(title=f"{record['label']} on {name} (protocol {record['protocol']})")
        for col in (f"level ({terrain['unit']})" if terrain['unit'] else "level", "success", "95% CI", "episodes", "speed (m/s)", "max |y| (m)"):
            table.add_column(col, justify="right")
        for lv in (lv for lv in record["levels"] if lv["terrain"] == name):
            speed, max_y = lv.get("mean_forward_speed_m_per_s"), lv.get("mean_max_abs_y_m")
            table.add_row(
                format_level(lv["level"]) + (" *" if lv["headroom"] else ""),
                f"{100 * lv['success_rate']:.0f}%",
                f"{100 * lv['ci95_low']:.0f}-{100 * lv['ci95_high']:.0f}%",
                f"{lv['successes']}/{lv['episodes']}",
                "-" if speed is None else f"{speed:.3f}",
                "-" if max_y is None else f"{max_y:.2f}",
            )
        console.print(table)
        hardest = terrain["hardest_level_passed"]
        console.print(f"  hardest level passed (>= 80%): "
                      f"{format_level(hardest) + ' ' + terrain['unit'] if hardest is not None else 'none'}; "
                      f"{auc_text(record, terrain)}"
                      + (f"; headroom AUC {terrain['headroom_auc']:.3f}" if terrain.get("headroom_auc") is not None else "")
                      + "  (* = headroom level beyond paper Table 4)", highlight=False, soft_wrap=True)


def auc_text(record: dict, terrain: dict) -> str:
    """A terrain's AUC for the run summary. The AUC is the terrain's only when the run covers all of
    the protocol's paper levels; over fewer it is labelled partial, naming how many it covers."""
    from hexbench.suite.tasks import format_level, load_suite

    name = terrain["terrain"]
    run_levels = [lv for lv in record["levels"] if lv["terrain"] == name and not lv["headroom"]]
    try:
        protocol_tasks = [t for t in load_suite(record["protocol"]).all_tasks if t.terrain == name]
    except ValueError:  # a protocol this install does not have: the run's own levels are all it knows
        protocol_tasks = []
    paper = {format_level(t.level) for t in protocol_tasks if not t.headroom}
    covered = {format_level(lv["level"]) for lv in run_levels}
    if terrain.get("auc") is None or not run_levels:
        return f"no AUC (none of the {len(paper)} paper levels run)" if paper else "no AUC (no paper level run)"
    auc = f"{terrain['auc']:.3f}"
    if not paper:
        return f"AUC over the {len(covered)} paper level(s) run {auc}"
    if not paper <= covered:
        return f"partial AUC {auc} (over {len(covered & paper)} of {len(paper)} paper levels; not the terrain's AUC)"
    per_level = protocol_tasks[0].episodes
    fewest = min(lv["episodes"] for lv in run_levels)
    if fewest < per_level:
        return f"AUC over paper levels {auc} (from {fewest} episode(s) per level; the protocol runs {per_level})"
    return f"AUC over paper levels {auc}"


ISOLATION_HELP = ("controller isolation: auto (bubblewrap where it works, else process), bubblewrap, process, "
                  "or none (in-process, debugging only; the leaderboard refuses such records)")


def _split_files(files: list[str]) -> tuple[list[str], list[str]]:
    """(the names that are controller files, a one-line problem for each of the others): the
    others are reported and the rest still run (`controller_file_problem`)."""
    from hexbench.suite.controller import controller_file_problem

    problems = {f: controller_file_problem(f) for f in files}
    return [f for f in files if not problems[f]], [p for p in problems.values() if p]


def _register_run(app: typer.Typer) -> None:
    @app.command("run")
    def run(
        files: list[str] = typer.Argument(..., help="controller file(s) defining make_controller(task)"),
        terrain: list[str] = typer.Option(None, "--terrain", help="rough, slopes or stairs (repeatable; default all)"),
        levels: str = typer.Option(None, "--levels", "--level", help="comma-separated levels in the paper's units "
                                   "(cm, deg)"),
        episodes: int = typer.Option(None, "--episodes", min=1, help="episodes per level (default: protocol's 20)"),
        workers: int = typer.Option(0, "--workers", min=0, help="worker processes (0: all cores)"),
        out: str = typer.Option(None, "--out", help="output directory (default runs/<name>-<protocol>)"),
        protocol: str = typer.Option("v1", "--protocol", help="protocol version"),
        record: bool = typer.Option(True, "--record/--no-record", help="write MCAP + Rerun logs per episode "
                                    "(action logs are always written)"),
        label: str = typer.Option(None, "--label", help="name in records (default: file name without .py)"),
        isolation: str = typer.Option("auto", "--isolation", help=ISOLATION_HELP),
        seed_key: str = typer.Option(None, "--seed-key", help="file with a secret key: episode seeds are derived from "
                                     "it (HMAC), so nobody can know the episodes in advance"),
        make_timeout: float = typer.Option(120.0, "--make-timeout", min=0.1,
                                           help="deadline for the controller process to start and build [s]"),
        engine: str = typer.Option("local", "--engine", help="where episodes run: local (a process pool on this "
                                   "machine) or ray (one Ray task per episode; pip install 'hexbench[ray]')"),
        address: str = typer.Option(None, "--address", help="with --engine ray: the cluster's address HOST:PORT "
                                    "(default: RAY_ADDRESS, else the cluster started last here, else a local one)"),
    ) -> None:
        """Evaluate controller files on the protocol; print a success table; write result.json and episodes.parquet."""
        import os
        from pathlib import Path

        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.evaluation import engines
        from hexbench.evaluation.evaluate import evaluate
        from hexbench.evaluation.isolation import landlock_abi
        from hexbench.evaluation.sandbox import resolve_isolation
        from hexbench.suite.seeds import SeedSet, read_seed_key
        from hexbench.suite.tasks import load_suite

        console = Console()
        err = Console(stderr=True, soft_wrap=True)
        try:
            tasks = load_suite(protocol).select(terrain or None, _parse_levels(levels))
            mode = resolve_isolation(isolation)
            seed_set = read_seed_key(seed_key) if seed_key else SeedSet()
            run_engine = engines.make_engine(engine, address)
        except (ValueError, HexbenchError) as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2)
        if mode == "process" and isolation == "auto":
            files = "Landlock keeps them to their files" if landlock_abi() else "the file system is not hidden"
            err.print(f"note: bubblewrap is not usable here; controllers run in plain child processes "
                      f"(--isolation process: {files}). Debian: apt-get install bubblewrap")
        if record:
            try:
                import hexbench.recording  # noqa: F401
            except ImportError:
                err.print("note: episode recording is not available in this install; running with --no-record")
                record = False
        runnable, problems = _split_files(files)
        for problem in problems:
            typer.echo(f"error: {problem}", err=True)
        failed = len(problems)
        if runnable and engine != "local":
            try:
                run_engine.connect()
            except HexbenchError as e:
                typer.echo(f"error: {e}", err=True)
                raise typer.Exit(2)
        n_workers = (workers or os.cpu_count() or 1) if engine == "local" or not runnable \
            else workers or run_engine.default_workers()
        where = "" if engine == "local" else f" on the {run_engine.describe()}" if runnable else ""
        try:
            for f in runnable:
                name = label if (label and len(files) == 1) else Path(f).stem
                out_dir = Path(out) / (name if len(files) > 1 else "") if out else Path("runs") / f"{name}-{protocol}"
                try:
                    with engines.using(run_engine):
                        result = evaluate(f, tasks, out_dir, episodes=episodes, workers=n_workers, record=record,
                                          label=name, isolation=mode, seed_set=seed_set, make_timeout_s=make_timeout)
                except HexbenchError as e:
                    result = None
                    typer.echo(f"error: {e}", err=True)
                else:
                    if result.error:
                        typer.echo(f"error: {result.error}", err=True)
                if result is None or result.error:
                    failed += 1
                    continue
                print_success_table(result.record, console)
                console.print(f"wrote {out_dir / 'result.json'} and {out_dir / 'episodes.parquet'} "
                              f"({result.record['provenance']['wall_time_s']:.1f} s, {n_workers} workers{where}, "
                              f"isolation {mode})", highlight=False)
        finally:
            run_engine.close()
        if failed:
            raise typer.Exit(1)

    @app.command("check")
    def check(
        files: list[str] = typer.Argument(..., help="controller file(s) to check"),
        steps: int = typer.Option(120, "--steps", min=1, help="control steps per terrain"),
        protocol: str = typer.Option("v1", "--protocol"),
        isolation: str = typer.Option("auto", "--isolation", help=ISOLATION_HELP),
        make_timeout: float = typer.Option(120.0, "--make-timeout", min=0.1,
                                           help="deadline for the controller process to start and build [s]"),
    ) -> None:
        """One short episode per terrain (easiest level) to catch a broken controller in seconds."""
        from pathlib import Path

        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.evaluation import sandbox
        from hexbench.evaluation.episode import EpisodeJob, run_episode
        from hexbench.suite.tasks import load_suite

        console = Console()
        try:
            suite = load_suite(protocol)
            mode = sandbox.resolve_isolation(isolation)
        except (ValueError, HexbenchError) as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(2)
        checkable, problems = _split_files(files)
        for problem in problems:
            typer.echo(f"error: {problem}", err=True)
        failed = len(problems)
        for f in checkable:
            try:
                for terrain_name in suite.terrains:
                    task = suite.task(terrain_name, suite.levels(terrain_name)[0])
                    row = run_episode(EpisodeJob(f, task, 0, task.seeds(1)[0], max_steps=steps, isolation=mode,
                                                 make_timeout_s=make_timeout))
                    console.print(f"{f}: {task.name}: ok ({row['steps']} steps, {row['end_reason'] or 'running'},"
                                  f" {row['progress_m']:.2f} m, isolation {mode})", highlight=False)
            except HexbenchError as e:
                typer.echo(f"error: {e}", err=True)
                failed += 1
            finally:
                sandbox.close_all()
        if failed:
            raise typer.Exit(1)
