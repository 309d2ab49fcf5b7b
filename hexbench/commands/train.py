"""`hexbench train FILE --terrain T`: train a baseline file on a terrain's curriculum (hexbench.train)."""

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
    ) -> None:
        """Train a baseline (PPO/SAC/TD3 per its CONFIG) on the paper's curriculum; resumes a run."""
        from rich.console import Console

        from hexbench.train import TrainError, TrainSettings, parse_override, train

        err = Console(stderr=True)
        try:
            settings = TrainSettings(
                baseline_path=file, terrain=terrain, total_steps=steps, seed=seed, workers=workers, out_dir=out,
                checkpoint_every_s=checkpoint_every_s, csv_every_s=csv_every_s,
                overrides=tuple(parse_override(o) for o in override),
                command="hexbench " + shlex.join(sys.argv[1:]), show_progress=progress,
            )
            run = train(settings)
        except TrainError as e:
            err.print(f"[red]error:[/red] {e}", highlight=False)
            raise typer.Exit(2) from None
        last = run["checkpoints"][-1] if run["checkpoints"] else None
        if last:
            err.print(f"done: {run['env_steps']} env steps, {run['wall_time_s']:.0f} s; "
                      f"last checkpoint {settings.run_dir / last['file']}", highlight=False)
