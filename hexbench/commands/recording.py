"""Episode-log commands: `hexbench episodes`, `hexbench replay`, `hexbench verify`, `hexbench export minari`."""

from __future__ import annotations

from pathlib import Path

import typer


def _fail(message: str, code: int = 1) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


def _episode_file(episode: str, suffix: str) -> Path:
    """EPISODE may be a .mcap or .rrd path, or a path without suffix; return the file with `suffix`."""
    p = Path(episode)
    if p.suffix in (".mcap", ".rrd"):
        p = p.with_suffix(suffix)
    elif not p.suffix:
        p = p.with_name(p.name + suffix)
    else:
        _fail(f"{episode}: expected an episode file (.mcap or .rrd)", 2)
    if not p.is_file():
        from hexbench.artifacts.files import file_kind

        _fail(f"{p}: is {file_kind(p.stat().st_mode)}; expected an episode file" if p.exists() else f"{p}: no such file", 2)
    return p


def find_controller(recorded: str) -> Path | None:
    """The controller file a record names: its path as recorded (absolute, or relative to the current
    folder), else relative to the repository; None where there is no such file."""
    from hexbench.artifacts.provenance import REPO_ROOT

    p = Path(recorded)
    for candidate in (p,) if p.is_absolute() else (Path.cwd() / p, REPO_ROOT / p):
        if candidate.is_file():
            return candidate
    return None


def controller_to_rerun(named: dict, controller: str | None) -> Path:
    """The controller file `--rerun` plays: --controller FILE, else the file a record names (`named`,
    its `controller` block) as `find_controller` finds it. RerunError (one line) where there is none."""
    from hexbench.replay.rerun import RerunError

    if not controller and not named.get("file"):
        raise RerunError("the record names no controller file to re-run (a measured record does)")
    found = Path(controller) if controller else find_controller(str(named["file"]))
    if found is None or not found.is_file():
        raise RerunError(f"{controller or named.get('file')}: no such controller file here; --rerun needs the file the "
                         f"record names (sha256 {str(named.get('sha256', ''))[:12]}): pass it with --controller FILE")
    return found


def controller_note(recorded: str, sha256: str) -> str:
    """One line on the controller file a run names: found here and the same file, changed, or absent
    (replaying from action logs never needs it)."""
    from hexbench.artifacts.files import sha256_file

    found = find_controller(recorded)
    if found is None:
        return (f"controller {recorded}: not found in the current folder or the repository "
                f"(not needed: episodes replay from their action logs)")
    if sha256_file(found) == sha256:
        return f"controller {recorded}: {found} is the file that made the episodes (sha256 matches)"
    return (f"controller {recorded}: {found} differs from the file that made the episodes "
            f"(recorded sha256 {sha256[:12]})")


def _episodes_table(run_dir: Path):
    """The run's episode index as a DataFrame with absolute file paths (episodes.parquet, else the .mcap files)."""
    import pandas as pd

    from hexbench.errors import InputError
    from hexbench.evaluation.evaluate import read_episode_index
    from hexbench.recording.reader import EpisodeFileError, read_episode

    index = run_dir / "episodes.parquet"
    record_dir = run_dir / "episodes"
    if index.is_file():
        try:
            table = read_episode_index(index)
        except InputError as e:
            _fail(str(e), 2)
        for kind in ("mcap", "rrd"):
            col = f"{kind}_path"
            if col in table:
                table[col] = [str(record_dir / p) if isinstance(p, str) and p else None for p in table[col]]
        return table
    files = sorted(run_dir.glob("*.mcap")) or sorted(record_dir.glob("*.mcap"))
    rows = []
    for f in files:
        try:
            log = read_episode(f, validate=False)
            e, o = log.episode, log.outcome
            rows.append({"episode_id": e.get("episode_id", f.stem), "terrain": e.get("terrain"),
                         "level": float(e.get("level", "nan")), "index": int(e.get("index", -1)),
                         "seed": int(e.get("seed", -1)), "success": o.get("success"), "end_reason": o.get("end_reason"),
                         "steps": o.get("steps"), "progress_m": o.get("progress_m"), "mcap_path": str(f),
                         "rrd_path": str(f.with_suffix(".rrd")) if f.with_suffix(".rrd").is_file() else None})
        except (EpisodeFileError, ValueError):  # not a hexbench episode, or malformed metadata: not listed
            continue
    return pd.DataFrame(rows)


def register(app: typer.Typer) -> None:
    @app.command("episodes")
    def episodes(
        run_dir: str = typer.Argument(..., help="a run directory (with episodes.parquet) or a folder of .mcap files"),
        terrain: str = typer.Option(None, "--terrain", help="only this terrain"),
        level: float = typer.Option(None, "--level", help="only this level (paper units)"),
        outcome: str = typer.Option(None, "--outcome", help="success, failure, or an end reason "
                                                            "(fall, lateral_deviation, stalled, step_limit)"),
        paths: bool = typer.Option(False, "--paths", help="print only the .mcap paths (for scripting)"),
    ) -> None:
        """List and filter the logged episodes of a run."""
        from rich.console import Console
        from rich.table import Table

        from hexbench.world.env import END_REASONS

        root = Path(run_dir)
        if not root.is_dir():
            _fail(f"{run_dir}: no such directory", 2)
        table = _episodes_table(root)
        if table.empty:
            _fail(f"{run_dir}: no episodes.parquet and no .mcap episode files", 2)
        if terrain is not None:
            if terrain not in set(table["terrain"]):
                _fail(f"no episodes on terrain {terrain!r}; terrains in this run: {', '.join(sorted(set(table['terrain'])))}", 2)
            table = table[table["terrain"] == terrain]
        if level is not None:
            table = table[(table["level"] - level).abs() < 1e-9]
        if outcome is not None:
            valid = ("success", "failure") + tuple(r for r in END_REASONS if r != "success")
            if outcome not in valid:
                _fail(f"unknown outcome {outcome!r}; valid: {', '.join(valid)}", 2)
            if outcome == "success":
                table = table[table["success"] == True]  # noqa: E712 (pandas mask)
            elif outcome == "failure":
                table = table[table["success"] != True]  # noqa: E712
            else:
                table = table[table["end_reason"] == outcome]
        if paths:
            for p in table.get("mcap_path", []):
                if p:
                    typer.echo(p)
            return
        out = Table(title=f"{len(table)} episodes in {run_dir}")
        for col in ("episode", "seed", "outcome", "steps", "progress [m]", "mcap", "rrd"):
            out.add_column(col)
        for _, r in table.iterrows():
            mcap, rrd = r.get("mcap_path"), r.get("rrd_path")
            out.add_row(str(r["episode_id"]), str(r["seed"]), str(r["end_reason"]), str(r["steps"]),
                        f"{r['progress_m']:.3f}" if r.get("progress_m") is not None else "",
                        "yes" if isinstance(mcap, str) and Path(mcap).is_file() else "-",
                        "yes" if isinstance(rrd, str) and Path(rrd).is_file() else "-")
        Console().print(out)

    @app.command("replay")
    def replay(
        episode: str = typer.Argument(..., help="an episode's .mcap or .rrd file"),
        summary: bool = typer.Option(False, "--summary", help="print a text summary instead of opening a viewer"),
    ) -> None:
        """Open a logged episode in the Rerun viewer (or print a summary with --summary).

        An episode recorded without an .rrd gets one built from its .mcap first."""
        if summary:
            from hexbench.recording.reader import EpisodeFileError, summary_text

            mcap = _episode_file(episode, ".mcap")
            try:
                typer.echo(summary_text(mcap))
            except EpisodeFileError as e:
                _fail(str(e))
            except (KeyError, ValueError, TypeError) as e:  # a CRC-valid file with odd contents
                _fail(f"{mcap}: not a complete hexbench episode log ({type(e).__name__}: {e})")
            return
        import shutil
        import subprocess
        import sys

        p = Path(episode)
        if p.suffix in (".mcap", ".rrd") and not p.with_suffix(".rrd").is_file() and p.with_suffix(".mcap").is_file():
            from hexbench.recording.reader import EpisodeFileError
            from hexbench.replay.rrd_from_mcap import rrd_from_mcap

            try:  # recorded without an .rrd: build it from the MCAP once
                rrd_from_mcap(p.with_suffix(".mcap"), p.with_suffix(".rrd"))
            except (EpisodeFileError, OSError) as e:
                _fail(f"cannot build the Rerun file from {p.with_suffix('.mcap')}: {e}")
        rrd = _episode_file(episode, ".rrd")
        exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
        if not Path(exe).exists():
            _fail("the Rerun viewer (`rerun`, from rerun-sdk) is not installed; use --summary for a text summary")
        raise typer.Exit(subprocess.call([exe, str(rrd)]))

    @app.command("verify")
    def verify(
        path: str = typer.Argument(..., help="a run folder (with result.json), or one episode's .mcap file"),
        sample: int = typer.Option(None, "--sample", min=1, help="replay this many episodes drawn at random (default all)"),
        workers: int = typer.Option(0, "--workers", min=0, help="replay processes (0: all cores)"),
        seed_key: str = typer.Option(None, "--seed-key", help="the key of a keyed seed set, to check its seeds"),
        engine: str = typer.Option("local", "--engine", help="where replays run: local (processes on this machine) "
                                   "or ray (tasks on a Ray cluster; the action logs travel with them)"),
        address: str = typer.Option(None, "--address", help="with --engine ray: the cluster's address HOST:PORT"),
        rerun: bool = typer.Option(False, "--rerun", help="play the episodes with the controller the record names "
                                   "instead, sandboxed, and check it chooses every recorded action and every row "
                                   "comes out as recorded (which replays them)"),
        controller: str = typer.Option(None, "--controller", help="with --rerun: the controller file, where it is not "
                                       "at the path the record names (it must be the same file: sha256)"),
    ) -> None:
        """Replay a run's episodes from their action logs alone (never the controller) and check every row,
        the summaries, the digest and the seeds; the first mismatch is named. With --rerun, the record's
        controller plays the same episodes in the sandbox instead: every action must be the recorded one
        and every row the record's, so the recorded actions are replayed once, by the re-run."""

        from hexbench.errors import HexbenchError

        p = Path(path)
        if p.is_dir():
            from hexbench.evaluation import engines
            from hexbench.replay.verify import read_run_record, verify_run
            from hexbench.suite.seeds import read_seed_key

            try:
                seed_set = read_seed_key(seed_key) if seed_key else None
                with engines.opened(engine, address) as replay_engine:
                    report = verify_run(p, sample=sample, workers=workers or replay_engine.default_workers(),
                                        seed_set=seed_set, progress=True, replay=not rerun)
            except HexbenchError as e:
                _fail(str(e), 2)
            if not report.ok:
                _fail(report.message)
            typer.echo(f"ok: {report.message}")
            record = read_run_record(p)
            named = record["controller"]
            if not rerun:
                typer.echo(controller_note(named["file"], named["sha256"]))
                return
            from hexbench.replay.rerun import rerun_episodes

            try:
                found = controller_to_rerun(named, controller)
                with engines.opened(engine, address) as rerun_engine:
                    result = rerun_episodes(p, record, list(report.episodes), found,
                                            workers=workers or rerun_engine.default_workers(), progress=True)
            except HexbenchError as e:
                _fail(str(e), 2)
            if not result.ok:
                _fail(result.message)
            typer.echo(f"ok: {result.message}")
            return
        if rerun:
            _fail(f"{path}: --rerun takes a run folder", 2)
        if not p.suffix and not p.with_name(p.name + ".mcap").is_file():
            _fail(f"{path}: no such run folder or episode file", 2)
        from hexbench.recording.reader import read_episode
        from hexbench.replay.recording_verify import verify_episode

        mcap = _episode_file(path, ".mcap")
        result = verify_episode(mcap)
        if not result.ok:
            _fail(result.message)
        typer.echo(f"ok: {result.message}")
        meta = read_episode(mcap, validate=False).episode
        if meta.get("controller_file"):
            typer.echo(controller_note(meta["controller_file"], meta.get("controller_sha256", "")))

    export = typer.Typer(help="Export logged episodes to other dataset formats.", no_args_is_help=True)

    @export.command("minari")
    def export_minari(
        run_dir: str = typer.Argument(..., help="a run folder written by `hexbench run` (recorded or not), or a "
                                                "folder of .mcap episode logs with their action logs"),
        dataset_id: str = typer.Option(None, "--dataset-id", help="Minari dataset id (default hexbench/<run>-<task>-v0;"
                                       " with several tasks, each task's name goes before the version)"),
    ) -> None:
        """Write Minari datasets (arrow format), one per task, from a run's episodes replayed from their action logs
        (optional extra `minari`)."""
        import shlex

        try:
            import minari  # noqa: F401
        except ImportError:
            _fail("minari is not installed; install the optional extra with: pip install 'hexbench[minari]'")
        from hexbench.errors import HexbenchError
        from hexbench.replay.minari_export import datasets_folder, export_run

        try:
            datasets = export_run(Path(run_dir), dataset_id, progress=True)
        except HexbenchError as e:
            _fail(str(e), 2)
        folder = datasets_folder(Path(run_dir))
        for d in datasets:
            note = "" if d.env_spec_problem is None else \
                f"; no env spec stored ({d.env_spec_problem}): make the env with gym.make({d.gym_id!r})"
            typer.echo(f"wrote Minari dataset {d.dataset_id} ({d.episodes} episodes, {d.steps} steps{note})")
        first = datasets[0]
        load = f"ds = minari.load_dataset({first.dataset_id!r})" + \
            ("; env = ds.recover_environment()" if first.env_spec_problem is None else "")
        typer.echo(f"in {folder}; load with: MINARI_DATASETS_PATH={shlex.quote(str(folder))} "
                   f"python -c \"import minari; {load}; print(ds.total_episodes, 'episodes')\"")

    app.add_typer(export, name="export")
