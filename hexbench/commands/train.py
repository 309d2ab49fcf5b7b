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
        terrain: str = typer.Option(..., "--terrain", help="rough, slopes or stairs (comma-separated with --seeds)"),
        steps: int = typer.Option(1_000_000, "--steps", help="total env-step budget (summed over workers)"),
        seed: int = typer.Option(0, "--seed", help="seed of the learner and the environments"),
        seeds: str = typer.Option(None, "--seeds", help="a batch: one run per terrain and seed, e.g. 0-4 or 0,2,5 "
                                  "(runs in OUT/<method>-<terrain>-seed<S>, summary OUT/<method>-runs.csv)"),
        engine: str = typer.Option("local", "--engine", help="with --seeds: where the runs train: local (processes "
                                   "on this machine) or ray (one Ray task per run)"),
        address: str = typer.Option(None, "--address", help="with --engine ray: the cluster's address HOST:PORT "
                                    "[default: RAY_ADDRESS, else the cluster started here, else a local one]"),
        parallel: int = typer.Option(None, "--parallel", help="with --seeds: runs at once [default local: cores / "
                                     "--workers; ray: as many as the cluster's CPUs hold]"),
        workers: int = typer.Option(1, "--workers", help="parallel environments (processes when > 1)"),
        out: Path = typer.Option(None, "--out", help="run directory [default: training/<method>-<terrain>-seed<S>]"),
        checkpoint_every_s: float = typer.Option(300.0, "--checkpoint-every", help="seconds between checkpoints"),
        checkpoint_every_steps: int = typer.Option(None, "--checkpoint-every-steps", min=1, help="env steps between "
                                                   "checkpoints, instead of seconds: the same checkpoints on any machine"),
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
        if seeds is not None:
            _train_batch(file, terrain, seeds, out, engine, address, parallel, dict(
                total_steps=steps, workers=workers, checkpoint_every_s=checkpoint_every_s, csv_every_s=csv_every_s,
                checkpoint_every_steps=checkpoint_every_steps, overrides=override, device=device, init_from=init_from,
                fixed_level=level, curriculum=curriculum, value_warmup_steps=value_warmup), progress)
            return
        if "," in terrain or engine != "local" or address or parallel is not None:
            typer.secho("error: several terrains, --engine, --address and --parallel are for a batch of runs: "
                        "add --seeds, e.g. --seeds 0-4", fg="red", err=True)
            raise typer.Exit(2)
        try:
            settings = TrainSettings(
                baseline_path=file, terrain=terrain, total_steps=steps, seed=seed, workers=workers, out_dir=out,
                checkpoint_every_s=checkpoint_every_s, csv_every_s=csv_every_s,
                checkpoint_every_steps=checkpoint_every_steps, overrides=tuple(parse_override(o) for o in override),
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

    @app.command("seed-run")
    def seed_run_command(
        file: Path = typer.Argument(..., help="baseline file with a CONFIG dataclass, e.g. baselines/sac.py"),
        terrain: str = typer.Option(..., "--terrain", help="rough, slopes or stairs"),
        seed: int = typer.Option(..., "--seed", help="seed of the learner and the environments (>= 0)"),
        steps: int = typer.Option(None, "--steps", min=1, help="env-step budget [default: 1M, every method's on the "
                                  "seeds page]"),
        workers: int = typer.Option(None, "--workers", min=1, help="processes for held-out, protocol and replayed "
                                    "episodes; training steps one environment [default: 1]"),
        sample: int = typer.Option(None, "--sample", min=0, help="episodes replayed from their action logs before "
                                   "the record is admitted, 0 for every one [default: 40]"),
        seeds_dir: Path = typer.Option(None, "--seeds-dir", help="where the seed-run folder goes [default: "
                                       "baselines/seeds]"),
        training_dir: Path = typer.Option(None, "--training-dir", help="where the training run goes [default: "
                                          "training]"),
        scoring_dir: Path = typer.Option(None, "--scoring-dir", help="where the scored copy and the protocol "
                                         "episodes' action logs go [default: runs/seed-runs]"),
        progress: bool = typer.Option(True, "--progress/--no-progress", help="show progress bars"),
    ) -> None:
        """Train one seed of a baseline's recipe from scratch, select, score and admit it: baselines/seeds/<method>-<terrain>-seed<S>/."""
        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.leaderboard.seed_pipeline import SeedRunPlan, make_seed_run

        err = Console(stderr=True, soft_wrap=True, highlight=False)
        given = {"budget_env_steps": steps, "workers": workers, "replay_sample": sample, "seeds_dir": seeds_dir,
                 "training_root": training_dir, "scoring_root": scoring_dir}
        options = {name: value for name, value in given.items() if value is not None}
        if options.get("replay_sample") == 0:
            options["replay_sample"] = None  # every episode
        try:
            plan = SeedRunPlan(baseline_path=file, terrain=terrain, seed=seed, show_progress=progress, **options)
            folder = make_seed_run(plan, say=err.print)
        except HexbenchError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        err.print(f"done: {folder} (run `hexbench leaderboard build` to put it on leaderboard/seeds/)")

    def _train_batch(file: Path, terrain: str, seeds: str, out: Path | None, engine: str, address: str | None,
                     parallel: int | None, options: dict, progress: bool) -> None:
        from rich.console import Console
        from rich.table import Table

        from hexbench.errors import HexbenchError
        from hexbench.evaluation import engines
        from hexbench.training.batch import TrainBatch, check_batch, parse_seeds, parse_terrains, run_batch
        from hexbench.training.settings import TrainSettings, parse_curriculum, parse_override

        err = Console(stderr=True)
        try:
            curriculum = options.pop("curriculum")
            template = TrainSettings(
                baseline_path=file, terrain="", command="", show_progress=False,
                curriculum=parse_curriculum(curriculum) if curriculum is not None else None,
                **{**options, "overrides": tuple(parse_override(o) for o in options["overrides"])})
            batch = TrainBatch(template, parse_terrains(terrain), parse_seeds(seeds),
                               out_root=out or Path("training"), argv=tuple(sys.argv[1:]))
            if parallel is not None and parallel < 1:
                raise engines.EngineError(f"--parallel must be >= 1 (got {parallel})")
            n_runs = len(check_batch(batch))
            with engines.opened(engine, address) as where:
                err.print(f"{n_runs} run{'s' * (n_runs != 1)} of {template.method} ({', '.join(batch.terrains)} x seeds "
                          f"{seeds}) on the {where.describe()}; folders under {batch.out_root}",
                          highlight=False, soft_wrap=True)
                rows = run_batch(batch, where, parallel, show_progress=progress)
        except HexbenchError as e:
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        table = Table(title=f"{template.method}: {len(rows)} runs ({batch.summary_path})")
        for col in ("terrain", "seed", "status", "env steps", "wall [s]", "success rate", "level (mean)"):
            table.add_column(col, justify="right")
        for r in rows:
            table.add_row(r["terrain"], str(r["seed"]), r["status"], f"{r['env_steps']:,}",
                          f"{r['wall_time_s']:.0f}" if r["wall_time_s"] is not None else "",
                          f"{r['success_rate']:.2f}" if r["success_rate"] is not None else "",
                          f"{r['curriculum_level_mean']:g}" if r["curriculum_level_mean"] is not None else "")
        Console().print(table)
        failed = [r for r in rows if r["status"] == "failed"]
        if failed:
            listed = "; ".join(f"{r['terrain']} seed {r['seed']}: {r['error']}" for r in failed)
            typer.secho(f"error: {len(failed)} of {len(rows)} runs failed ({listed})", fg="red", err=True)
            raise typer.Exit(1)

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
        bands: bool = typer.Option(False, "--bands", help="one line per method and recipe: the mean over its seeds "
                                                          "with a 95% band (paper Fig. 4 over seeds)"),
    ) -> None:
        """Plot episode reward, success rate and curriculum level vs env steps (paper Fig. 4) from progress CSVs."""
        from rich.console import Console

        from hexbench.errors import HexbenchError
        from hexbench.training.curves import plot_bands, plot_curves

        console = Console(stderr=True)
        try:
            written = (plot_bands(sources, out, title, max_env_steps) if bands
                       else plot_curves(sources, out, title, copy_csv, max_env_steps))
        except (HexbenchError, OSError, ValueError) as e:  # CurvesError, OutputError; pandas' parse errors
            typer.secho(f"error: {e}", fg="red", err=True)
            raise typer.Exit(2) from None
        for path in written:
            console.print(f"wrote {path}", highlight=False, soft_wrap=True)
