"""`hexbench train FILE --terrain T`: train a baseline file on a terrain's curriculum (hexbench.training.loop);
`hexbench checkpoints publish|select|verify` and `hexbench curves`."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command("train")
    def train_command(
        file: Path = typer.Argument(..., help="baseline file with a CONFIG dataclass, e.g. baselines/ppo_cpg.py"),
        terrain: str = typer.Option(..., "--terrain", help="rough, slopes or stairs"),
        steps: int = typer.Option(1_000_000, "--steps", help="total env-step budget (summed over workers)"),
        seed: int = typer.Option(0, "--seed", help="seed of the learner and the environments"),
        workers: int = typer.Option(1, "--workers", help="parallel environments (processes when > 1)"),
        out: Path = typer.Option(None, "--out", help="run directory [default: training/<method>-<terrain>-seed<S>]"),
        checkpoint_every_s: float = typer.Option(300.0, "--checkpoint-every", help="seconds between checkpoints"),
        csv_every_s: float = typer.Option(60.0, "--csv-every", help="seconds between progress.csv rows"),
        override: list[str] = typer.Option([], "--set", help="override a CONFIG field, NAME=VALUE (repeatable)"),
        progress: bool = typer.Option(True, "--progress/--no-progress", help="show the progress bar"),
        device: str = typer.Option("cpu", "--device", help="torch device of the learner: cpu or cuda (SAC/TD3 gain most)"),
        level: float = typer.Option(None, "--level", help="train at this one level of the task suite, without the curriculum"),
        curriculum: str = typer.Option(None, "--curriculum", help="replace the paper's curriculum: START:STEP:TOP levels in the terrain's unit, e.g. 18:0.5:21 (fine-tuning beyond the paper's top)"),
        value_warmup: int = typer.Option(0, "--value-warmup", help="PPO: env steps during which only the fresh value function learns (the actor stays as initialised: loaded by --init-from, or fresh)"),
        init_from: Path = typer.Option(None, "--init-from", help="start a new PPO run from shipped weights, e.g. baselines/checkpoints/ppo_cpg-rough.zip (std and value head from scratch)"),
    ) -> None:
        """Train a baseline (PPO/SAC/TD3 per its CONFIG) on the paper's curriculum; resumes a run."""
        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.training.loop import train
        from hexbench.training.settings import TrainSettings, parse_curriculum, parse_override

        err = Console(stderr=True)
        try:
            settings = TrainSettings(
                baseline_path=file, terrain=terrain, total_steps=steps, seed=seed, workers=workers, out_dir=out,
                checkpoint_every_s=checkpoint_every_s, csv_every_s=csv_every_s,
                overrides=tuple(parse_override(o) for o in override),
                command="hexbench " + shlex.join(sys.argv[1:]), show_progress=progress, device=device,
                init_from=init_from, fixed_level=level,
                curriculum=parse_curriculum(curriculum) if curriculum is not None else None,
                value_warmup_steps=value_warmup,
            )
            run = train(settings)
        except HexbenchError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        last = run["checkpoints"][-1] if run["checkpoints"] else None
        if last:
            err.print(f"done: {run['env_steps']} env steps, {run['wall_time_s']:.0f} s; "
                      f"last checkpoint {settings.run_dir / last['file']}", highlight=False, soft_wrap=True)

    checkpoints = typer.Typer(help="Shipped baseline weights: publish a run's checkpoint, verify the manifest.",
                              no_args_is_help=True)
    app.add_typer(checkpoints, name="checkpoints")

    @checkpoints.command("publish")
    def publish_command(
        run_dir: Path = typer.Argument(..., help="training run directory (holds run.json)"),
        which: str = typer.Option("best", "--checkpoint", help="best (training metrics), heldout (best of `checkpoints select`), last, or the env-step count of one"),
        dest: Path = typer.Option(Path("baselines/checkpoints"), "--dest", help="shipped checkpoints folder"),
    ) -> None:
        """Copy a run's checkpoint (policy weights only) into baselines/checkpoints/ with its manifest entry."""
        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.training.publish import publish_checkpoint

        console = Console(stderr=True)
        try:
            entry = publish_checkpoint(run_dir, dest, which)
        except HexbenchError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        console.print(f"published {dest / entry['file']} ({entry['status']}; sha256 {entry['sha256'][:12]}...)",
                      highlight=False, soft_wrap=True)

    @checkpoints.command("select")
    def select_command(
        run_dir: Path = typer.Argument(..., help="training run directory (holds run.json)"),
        episodes: int = typer.Option(3, "--episodes", help="held-out episodes per selection level"),
        levels: list[float] = typer.Option([], "--level", help="selection level (repeatable) [default: hexbench.training.selection.SELECTION_LEVELS]"),
        stride: int = typer.Option(1, "--stride", help="score every N-th checkpoint (and the last)"),
        min_env_steps: int = typer.Option(None, "--min-env-steps", help="score no checkpoint before this many env steps"),
        max_env_steps: int = typer.Option(None, "--max-env-steps", help="score no checkpoint beyond this many env steps"),
        top: int = typer.Option(None, "--top", help="only the N best-scored so far (top them up to --episodes)"),
        workers: int = typer.Option(1, "--workers", help="processes"),
    ) -> None:
        """Score a run's checkpoints by their deterministic policy on held-out episodes (not the protocol's)."""
        from rich.console import Console
        from rich.table import Table

        from hexbench.training.selection import SelectionError, checkpoint_score, select

        console = Console(stderr=True)
        try:
            table = select(run_dir, episodes=episodes, levels=tuple(levels) or None, stride=stride,
                           min_env_steps=min_env_steps, max_env_steps=max_env_steps, top=top, workers=workers)
        except SelectionError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        out = Table(title=f"{run_dir}: held-out episodes at levels {', '.join(f'{lv:g}' for lv in table['levels'])}")
        for col in ("env steps", "successes", "rate, 95% lower bound", "mean progress \\[m]", "ends"):
            out.add_column(col, justify="right")
        for sha, entry in sorted(table["checkpoints"].items(), key=lambda kv: kv[1]["env_steps"]):
            lower, progress_m, n = checkpoint_score(entry, table["goal_distance_m"])
            ends: dict[str, int] = {}
            for e in entry["episodes"]:
                ends[e["end_reason"]] = ends.get(e["end_reason"], 0) + 1
            mark = " *" if sha == table["best"]["sha256"] else ""
            out.add_row(f"{entry['env_steps']}{mark}", f"{sum(e['success'] for e in entry['episodes'])}/{n}",
                        f"{lower:.2f}", f"{progress_m:.2f}", ", ".join(f"{k} {v}" for k, v in sorted(ends.items())))
        Console().print(out)
        console.print(f"best (*): {table['best']['file']}; ship it with "
                      f"`hexbench checkpoints publish {run_dir} --checkpoint heldout`", highlight=False, soft_wrap=True)

    @checkpoints.command("verify")
    def verify_command(
        dest: Path = typer.Option(Path("baselines/checkpoints"), "--dir", help="shipped checkpoints folder"),
    ) -> None:
        """Check every shipped checkpoint's sha256 against the manifest."""
        from rich.console import Console

        from hexbench.artifacts.manifest import CheckpointError, read_manifest, verify_checkpoint

        console = Console(stderr=True)
        try:
            manifest = read_manifest(dest)
        except CheckpointError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        bad = 0
        for key, entry in sorted(manifest["checkpoints"].items()):
            try:
                verify_checkpoint(dest / entry["file"], entry["sha256"])
                console.print(f"ok   {key}: {entry.get('status', '')}", highlight=False, soft_wrap=True)
            except CheckpointError as e:
                bad += 1
                console.print(f"[red]bad[/red]  {key}: {e}", highlight=False, soft_wrap=True)
        if bad:
            raise typer.Exit(1)

    @app.command("curves")
    def curves_command(
        sources: list[Path] = typer.Argument(..., help="run directories (training/...) or progress CSVs"),
        out: Path = typer.Option(..., "--out", help="PNG to write, e.g. leaderboard/curves/rough.png"),
        title: str = typer.Option("", "--title", help="figure title"),
        copy_csv: bool = typer.Option(True, "--copy-csv/--no-copy-csv", help="copy run CSVs next to the PNG"),
        max_env_steps: int | None = typer.Option(None, "--max-env-steps",
                                                 help="plot every run's first N env steps only (one budget)"),
    ) -> None:
        """Plot episode reward, success rate and curriculum level vs env steps (paper Fig. 4) from progress CSVs."""
        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.training.curves import plot_curves

        console = Console(stderr=True)
        try:
            written = plot_curves(sources, out, title, copy_csv, max_env_steps)
        except (HexbenchError, OSError, ValueError) as e:  # CurvesError, OutputError; pandas' parse errors
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        for path in written:
            console.print(f"wrote {path}", highlight=False, soft_wrap=True)
