"""The epsilon search of paper section 3.2 (`hexbench sweep epsilon --terrain T`).

The paper trains PPO-CPG at the terrain's hardest curriculum level for 10 trials of 100,000 steps
at each eps in {0, 0.1, ..., 1} and keeps the eps with the highest average reward (0.6 rough, 0.4
slopes, 0.3 stairs). Here each (eps, trial) is one ordinary training run (hexbench.training.loop) with
`residual_scale=eps` at the level `CURRICULA[terrain].max_level`, no curriculum, seed = trial index;
the score of a trial is its mean reward per env step over the whole trial (well defined even when a
short trial finishes few 4000-step episodes); the mean episode reward of its last 20 episodes is
reported beside it. Trials are run directories under the sweep folder, so an interrupted sweep
resumes where it stopped. Defaults are short (the paper's budget is 11 x 10 x 100k = 11M steps).

`hexbench sweep plot FOLDER_OR_CSV... --out PNG` draws one panel per terrain (score against eps,
every trial and their mean, the best eps and the paper's marked) and copies each epsilon.csv next
to the PNG as epsilon-<terrain>.csv, so the figure can be redrawn from committed data alone.
"""

from __future__ import annotations

import csv
import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.artifacts.files import atomic_path
from hexbench.errors import HexbenchError
from hexbench.training.loop import train
from hexbench.training.runs import read_run
from hexbench.training.settings import TRAIN_TERRAINS, TrainError, TrainSettings
from hexbench.training.wrappers import CURRICULA

SWEEP_COLUMNS = ("terrain", "eps", "trial", "seed", "level", "env_steps", "wall_time_s", "mean_step_reward",
                 "mean_episode_reward", "episodes", "success_rate")
PAPER_EPS: dict[str, float] = {"rough": 0.6, "slopes": 0.4, "stairs": 0.3}


@dataclass(frozen=True)
class EpsilonSweep:
    terrain: str
    baseline_path: Path = Path("baselines/ppo_cpg.py")
    eps_values: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(11))
    trials: int = 1
    steps_per_trial: int = 4096  # env steps
    out_dir: Path | None = None  # None -> training/sweep-epsilon-<terrain>
    overrides: tuple[tuple[str, object], ...] = ()

    @property
    def folder(self) -> Path:
        return Path(self.out_dir) if self.out_dir else Path("training") / f"sweep-epsilon-{self.terrain}"

    @property
    def level(self) -> float:
        return CURRICULA[self.terrain].max_level


def run_sweep(sweep: EpsilonSweep, command: str = "", progress_callback=None) -> list[dict]:
    """Train every (eps, trial); write <folder>/epsilon.csv; return its rows."""
    if sweep.terrain not in TRAIN_TERRAINS:
        raise TrainError(f"unknown terrain {sweep.terrain!r}; valid terrains: {', '.join(TRAIN_TERRAINS)}")
    bad = [e for e in sweep.eps_values if not 0.0 <= e <= 1.0]
    if bad:
        raise TrainError(f"eps values must lie in [0, 1]; got {bad}")
    if sweep.trials < 1 or sweep.steps_per_trial < 1:
        raise TrainError("--trials and --steps must be >= 1")
    rows = []
    for eps in sweep.eps_values:
        for trial in range(sweep.trials):
            run_dir = sweep.folder / f"eps{eps:.2f}-trial{trial}"
            settings = TrainSettings(
                baseline_path=sweep.baseline_path, terrain=sweep.terrain, total_steps=sweep.steps_per_trial,
                seed=trial, workers=1, out_dir=run_dir, overrides=sweep.overrides + (("residual_scale", float(eps)),),
                command=command, show_progress=False, fixed_level=sweep.level, checkpoint_every_s=1e9,
            )
            train(settings)
            run = read_run(run_dir)
            last = run["checkpoints"][-1]
            rows.append({"terrain": sweep.terrain, "eps": eps, "trial": trial, "seed": trial, "level": sweep.level,
                         "env_steps": last["env_steps"], "wall_time_s": last["wall_time_s"],
                         "mean_step_reward": last.get("mean_step_reward"),
                         "mean_episode_reward": last.get("mean_episode_reward"),
                         "episodes": last.get("episodes"), "success_rate": last.get("success_rate")})
            if progress_callback:
                progress_callback(rows[-1])
    with atomic_path(sweep.folder / "epsilon.csv") as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=SWEEP_COLUMNS)
        w.writeheader()
        w.writerows({k: ("" if v is None else v) for k, v in r.items()} for r in rows)
    return rows


def best_eps(rows: list[dict]) -> tuple[float, dict[float, float]]:
    """(eps with the highest mean step reward over its trials, {eps: that mean})."""
    by_eps: dict[float, list[float]] = {}
    for r in rows:
        if r["mean_step_reward"] is not None:
            by_eps.setdefault(r["eps"], []).append(r["mean_step_reward"])
    means = {e: float(np.mean(v)) for e, v in by_eps.items()}
    if not means:
        return math.nan, means
    return max(means, key=means.get), means


class SweepError(HexbenchError):
    """A sweep result cannot be read or plotted; the message is one line."""


def read_sweep(source: Path) -> tuple[Path, str, list[dict]]:
    """(the CSV read, terrain, rows) of a sweep folder or its epsilon.csv; numbers parsed, empty cells None."""
    source = Path(source)
    csv_path = source / "epsilon.csv" if source.is_dir() else source
    if not source.exists():
        raise SweepError(f"{source}: no such sweep folder or epsilon CSV")
    if not csv_path.is_file():
        raise SweepError(f"{source}: no sweep result (expected {csv_path}; run `hexbench sweep epsilon` first)")
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in SWEEP_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise SweepError(f"{csv_path}: not a hexbench sweep CSV (missing columns: {', '.join(missing)})")
        raw = list(reader)
    if not raw:
        raise SweepError(f"{csv_path}: the sweep has no rows")
    terrains = {r["terrain"] for r in raw}
    if len(terrains) != 1 or not terrains <= set(PAPER_EPS):
        raise SweepError(f"{csv_path}: expected one terrain of {', '.join(PAPER_EPS)}; found {', '.join(sorted(terrains))}")
    try:
        rows = [{k: (r[k] if k == "terrain" else None if r[k] == "" else float(r[k])) for k in SWEEP_COLUMNS}
                for r in raw]
    except ValueError as e:
        raise SweepError(f"{csv_path}: not a hexbench sweep CSV ({e})") from None
    return csv_path, terrains.pop(), rows


def plot_sweeps(sources: list[Path], out_png: Path) -> list[Path]:
    """One panel per sweep: mean reward per env step against eps. Returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hexbench.training.curves import save_png

    if not sources:
        raise SweepError("no sweeps given; pass sweep folders (training/sweep-epsilon-...) or epsilon CSVs")
    loaded = [read_sweep(Path(s)) for s in sources]
    terrains = [t for _, t, _ in loaded]
    if len(set(terrains)) != len(terrains):
        raise SweepError(f"one sweep per terrain, please; got {', '.join(terrains)}")
    fig, axes = plt.subplots(1, len(loaded), figsize=(4.2 * len(loaded), 3.8), squeeze=False)
    for ax, (_, terrain, rows) in zip(axes[0], loaded):
        best, means = best_eps(rows)
        scored = [r for r in rows if r["mean_step_reward"] is not None]
        ax.scatter([r["eps"] for r in scored], [r["mean_step_reward"] for r in scored], s=12, color="0.6",
                   label="one trial", zorder=2)
        xs = sorted(means)
        ax.plot(xs, [means[x] for x in xs], "o-", color="C0", label="mean over trials", zorder=3)
        ax.axvline(best, color="C0", linestyle=":", label=f"best here: {best:g}")
        ax.axvline(PAPER_EPS[terrain], color="C3", linestyle="--", label=f"paper: {PAPER_EPS[terrain]:g}")
        trials = int(max(r["trial"] for r in rows)) + 1
        steps = int(max(r["env_steps"] for r in rows))
        ax.set_title(f"{terrain}, level {rows[0]['level']:g}: {trials} trial(s) x {steps:,} steps", fontsize=9)
        ax.set_xlabel("eps (residual scale)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("mean reward per env step")
    fig.suptitle("epsilon search (paper 3.2)\nPPO-CPG trained at the hardest curriculum level", fontsize=10)
    fig.tight_layout()
    out_png = save_png(fig, out_png)
    written = [out_png]
    for csv_path, terrain, _ in loaded:
        dest = out_png.parent / f"epsilon-{terrain}.csv"
        if csv_path.resolve() != dest.resolve():
            shutil.copyfile(csv_path, dest)
        written.append(dest)
    return written
