"""`hexbench sweep epsilon --terrain T`: the residual-scale search of paper 3.2 (hexbench.training.sweep)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    sweep = typer.Typer(help="Hyper-parameter searches from the paper.", no_args_is_help=True)
    app.add_typer(sweep, name="sweep")

    @sweep.command("epsilon")
    def epsilon_command(
        terrain: str = typer.Option(..., "--terrain", help="rough, slopes or stairs"),
        values: str = typer.Option("0,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1", "--values", help="eps values, comma-separated"),
        trials: int = typer.Option(1, "--trials", help="trials per eps (seeds 0..N-1); the paper uses 10"),
        steps: int = typer.Option(4096, "--steps", help="env steps per trial; the paper uses 100000"),
        baseline: Path = typer.Option(Path("baselines/ppo_cpg.py"), "--baseline", help="cpg_residual baseline file"),
        out: Path = typer.Option(None, "--out", help="sweep folder [default: training/sweep-epsilon-<terrain>]"),
        override: list[str] = typer.Option([], "--set", help="override a CONFIG field, NAME=VALUE (repeatable)"),
    ) -> None:
        """Train PPO-CPG at the terrain's hardest level for each eps; report the best (paper 3.2)."""
        from rich.console import Console
        from rich.progress import Progress
        from rich.table import Table

        from hexbench.errors import HexbenchError
        from hexbench.training.settings import TrainError, parse_override
        from hexbench.training.sweep import PAPER_EPS, EpsilonSweep, best_eps, run_sweep

        console = Console(stderr=True)
        try:
            eps_values = tuple(float(v) for v in values.split(",") if v.strip())
        except ValueError:
            typer.secho(f"error: --values {values!r} is not a comma-separated list of numbers in [0, 1]", fg="red", err=True)
            raise typer.Exit(2) from None
        try:
            overrides = tuple(parse_override(o) for o in override)
        except TrainError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        spec = EpsilonSweep(terrain=terrain, baseline_path=baseline, eps_values=eps_values, trials=trials,
                            steps_per_trial=steps, out_dir=out, overrides=overrides)
        total = len(eps_values) * max(trials, 1)
        with Progress(console=console) as progress:
            task = progress.add_task(f"eps sweep {terrain}", total=total)
            try:
                rows = run_sweep(spec, "hexbench " + shlex.join(sys.argv[1:]),
                                 progress_callback=lambda row: progress.advance(task))
            except HexbenchError as e:
                typer.secho(f"error: {e}", fg="red", err=True)
                raise typer.Exit(2) from None
        best, means = best_eps(rows)
        table = Table(title=f"eps sweep, {terrain} level {spec.level:g}, {trials} trial(s) x {steps} steps")
        for col in ("eps", "mean reward / step", "mean episode reward", "success"):
            table.add_column(col)
        for eps in eps_values:
            rs = [r for r in rows if r["eps"] == eps]
            ep = [r["mean_episode_reward"] for r in rs if r["mean_episode_reward"] is not None]
            sr = [r["success_rate"] for r in rs if r["success_rate"] is not None]
            table.add_row(f"{eps:g}", f"{means.get(eps, float('nan')):.3f}",
                          f"{sum(ep) / len(ep):.1f}" if ep else "-", f"{100 * sum(sr) / len(sr):.0f}%" if sr else "-")
        Console().print(table)
        Console().print(f"best eps {best:g} (paper: {PAPER_EPS[terrain]:g}); rows in {spec.folder / 'epsilon.csv'}")

    @sweep.command("plot")
    def plot_command(
        sources: list[Path] = typer.Argument(..., help="sweep folders or their epsilon.csv, one per terrain"),
        out: Path = typer.Option(Path("leaderboard/epsilon/epsilon.png"), "--out", help="PNG to write"),
    ) -> None:
        """Plot eps sweeps (score against eps, best and paper's eps marked); copy their CSVs beside the PNG."""
        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.training.sweep import plot_sweeps

        try:
            written = plot_sweeps(sources, out)
        except HexbenchError as e:  # SweepError, OutputError
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        Console().print("wrote " + ", ".join(str(p) for p in written), soft_wrap=True)
