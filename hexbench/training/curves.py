"""Learning curves (paper Fig. 4): episode reward and curriculum level vs env steps, from runs' progress.csv.

    hexbench curves training/ppo_cpg-rough-seed0 training/ppo-rough-seed0 --out leaderboard/curves/rough.png

Each run directory contributes one line per panel: at every logged env-step count, the mean over
its envs of the mean episode reward and of the success rate of their last 20 episodes, and the mean
curriculum level (the success rate shows progress within a level, e.g. in the first 60k steps). A run
that has not reached its env-step budget is labelled "partial: N of M steps", one trained without
the early-end penalty says so; labels are run directory names, with the initial policy std and
whether rewards were normalised. The CSVs plotted are copied next to the PNG as <run directory name>.csv, so the figure can be regenerated from
committed data alone (`hexbench curves leaderboard/curves/*.csv`).
"""

from __future__ import annotations

import json
import math
import shutil
import textwrap
from pathlib import Path

import pandas as pd

from hexbench.artifacts.files import atomic_path, write_json_atomic
from hexbench.errors import HexbenchError
from hexbench.training.runs import CSV_COLUMNS

LEGEND_LINE_CHARS = 120  # run labels wrap at this many characters
LEGEND_LINE_IN = 0.13  # height of one legend line at font size 7 [inch]


METHOD_COLOURS: dict[str, str] = {"ppo_cpg": "C0", "ppo": "C3", "hrl": "C2", "sac_cpg": "C1", "td3_cpg": "C4",
                                   "sac": "C5", "td3": "C6"}
SEED_LINESTYLES: tuple[str, ...] = ("-", "--", ":", "-.")
# colours for a method's second and further configs (ablations) and for unknown methods
EXTRA_COLOURS: tuple[str, ...] = ("C7", "C8", "C9", "black", "olive", "teal")


class CurvesError(HexbenchError):
    """A run or CSV cannot be plotted; the message is one line."""


def load_progress(source: Path, max_env_steps: int | None = None) -> tuple[pd.DataFrame, str, dict | None]:
    """(per-step aggregate over envs, label, run.json or None) for a run directory or a progress CSV.

    max_env_steps: keep only the rows up to that many env steps (a common budget for all runs); a
    run is then "partial" only if it stopped short of both its own budget and that window.
    """
    source = Path(source)
    run = None
    if source.is_dir():
        csv_path = source / "progress.csv"
        run_path = source / "run.json"
        run = json.loads(run_path.read_text()) if run_path.exists() else None
    else:
        csv_path = source
        side = source.with_suffix(".run.json")
        run = json.loads(side.read_text()) if side.exists() else None
    if not csv_path.is_file():
        raise CurvesError(f"{source}: no progress CSV (expected {csv_path})")
    df = pd.read_csv(csv_path)
    missing = [c for c in CSV_COLUMNS if c not in df.columns]
    if missing:
        raise CurvesError(f"{csv_path}: not a hexbench progress CSV (missing columns: {', '.join(missing)})")
    agg = df.groupby("env_steps", as_index=False).agg(
        wall_time_s=("wall_time_s", "max"), mean_episode_reward=("mean_episode_reward", "mean"),
        success_rate=("success_rate", "mean"), curriculum_level=("curriculum_level", "mean"),
        episodes=("episodes", "sum"))
    last_logged = int(agg["env_steps"].max()) if len(agg) else 0
    if max_env_steps is not None:
        agg = agg[agg["env_steps"] <= max_env_steps].reset_index(drop=True)
    if run:
        # the run directory's name (or its CSV copy's stem): runs of one method, terrain and seed
        # under different config revisions (docs/changelog.md: -v2, -v3, -v4) stay apart in the legend
        label = (source.resolve().name if source.is_dir() else source.stem) + recipe_description(run)
        total = run.get("total_steps", 0)
        last = max(run.get("env_steps", 0), last_logged)
        if max_env_steps is None and (run.get("env_steps", 0) < total or last_logged < total):
            label += f" (partial: {last_logged:,} of {total:,} steps)"
        elif max_env_steps is not None and last < total and last < max_env_steps:
            label += f" (partial: {last:,} of {total:,} steps)"
        elif max_env_steps is not None and total < max_env_steps:
            label += f" (budget {total:,} steps)"
    else:
        label = csv_path.stem
    return agg, label, run


def recipe_description(run: dict) -> str:
    """What of a run's recipe its label shows: exploration, reward scaling, warm start, options."""
    label = ""
    cfg = run.get("config") or {}
    if cfg.get("log_std_init") is not None:
        std = math.exp(cfg["log_std_init"])
        # under gSDE the std is that of the exploration matrix's entries, held for sde_sample_freq steps
        label += (f" (gSDE, matrix std {std:.2f}, new every {cfg.get('sde_sample_freq')} steps" if cfg.get("use_sde")
                  else f" (std {std:.2f}")
        label += ", normalised rewards)" if cfg.get("normalize_reward") else ")"
    if cfg.get("action_noise_std"):  # TD3's exploration: Gaussian noise on the action (SAC's is 0: none)
        label += f" (action noise std {cfg['action_noise_std']:g})"
    if cfg.get("train_freq") is not None:  # off-policy: updates per env step and critic size
        steps = cfg.get("gradient_steps") or 1  # SB3: -1 means as many updates as env steps collected
        updates = 1.0 if steps < 0 else steps / cfg["train_freq"]
        critics = cfg.get("critic_net_arch") or cfg.get("net_arch") or ()
        label += (f", {updates:g} update{'' if updates == 1 else 's'} per env step, "
                  f"critics [{', '.join(str(n) for n in critics)}]")
    if (cfg.get("decision_interval_steps") or 1) != 1:
        label += f", a decision every {cfg['decision_interval_steps']} control steps"
    if run.get("init_from"):
        label += f", from {run['init_from']['manifest_key']} at {run['init_from']['source_env_steps']:,}"
    if run.get("value_warmup_steps"):
        label += f", value warm-up {run['value_warmup_steps']:,}"
    if run.get("curriculum_levels"):
        c = run["curriculum_levels"]
        label += f", curriculum {c['start_level']:g}:{c['level_step']:g}:{c['max_level']:g}"
    if cfg.get("arrival_bonus"):
        label += ", arrival bonus"
    if cfg.get("end_terms_per_decision") and (cfg.get("decision_interval_steps") or 1) != 1:
        label += " (end terms per decision)"
    if cfg.get("heading_hold"):
        label += ", turn from a heading hold"
    if not cfg.get("early_end_penalty", False):
        label += ", no early-end penalty"  # the reward of Table 1 as written (docs/training.md)
    return label


def save_png(fig, out_png: Path) -> Path:
    """Write a matplotlib figure as a PNG atomically (no partial file if it fails) and close it."""
    import matplotlib.pyplot as plt

    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(out_png) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return out_png


# run.json fields of `hexbench train` options that change how a run learns beside its config
TRAINING_OPTION_KEYS: tuple[str, ...] = ("value_warmup_steps", "curriculum_levels", "fixed_level")


def recipe_key(method: str, run: dict | None) -> tuple[str, str]:
    """(method, recipe): runs that differ only in their seed share it."""
    run = run or {}
    recipe = {"config": run.get("config"), "init_sha256": (run.get("init_from") or {}).get("sha256"),
              **{k: run.get(k) for k in TRAINING_OPTION_KEYS}}
    return method, json.dumps(recipe, sort_keys=True)


def line_styles(runs: list[tuple[str, dict | None]]) -> list[dict[str, str]]:
    """Colour and line style per (method, run.json) so that seeds read as a group: one colour per
    method and training recipe (config, warm-start source, value warm-up, curriculum or fixed level;
    a method's first recipe gets the method's colour, another, an ablation, the next free one), one
    line style per seed within it."""
    runs_of_group: dict[tuple[str, str], int] = {}
    group_colour: dict[tuple[str, str], str] = {}
    styles = []
    for method, run in runs:
        group = recipe_key(method, run)
        if group not in group_colour:
            first_of_method = all(m != method for m, _ in group_colour)
            extra = sum(c in EXTRA_COLOURS for c in group_colour.values())
            group_colour[group] = (METHOD_COLOURS.get(method) if first_of_method else None) \
                or EXTRA_COLOURS[extra % len(EXTRA_COLOURS)]
        k = runs_of_group[group] = runs_of_group.get(group, -1) + 1
        styles.append({"color": group_colour[group], "linestyle": SEED_LINESTYLES[k % len(SEED_LINESTYLES)]})
    return styles


def plot_curves(sources: list[Path], out_png: Path, title: str = "", copy_csv: bool = True,
                max_env_steps: int | None = None) -> list[Path]:
    """Write the three-panel PNG (and copies of the CSVs next to it); returns the files written.

    max_env_steps: plot every run's first that many env steps only (methods at one budget).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not sources:
        raise CurvesError("no runs given; pass run directories (training/...) or progress CSVs")
    if max_env_steps is not None and max_env_steps <= 0:
        raise CurvesError(f"--max-env-steps must be a positive number of env steps, got {max_env_steps}")
    loaded = [load_progress(Path(s), max_env_steps) for s in sources]
    fig, (ax_r, ax_s, ax_l) = plt.subplots(3, 1, figsize=(9, 10.5), sharex=True, height_ratios=(3, 2, 2))
    styles = line_styles([(run.get("method") if run else Path(source).stem.split("-")[0], run)
                          for source, (_agg, _label, run) in zip(sources, loaded)])
    labels = ["\n".join(textwrap.wrap(label, LEGEND_LINE_CHARS)) for _agg, label, _run in loaded]
    for (agg, _label, _run), label, style in zip(loaded, labels, styles):
        style = {**style, "label": label}
        ax_r.plot(agg["env_steps"], agg["mean_episode_reward"], **style)
        ax_s.plot(agg["env_steps"], agg["success_rate"], **style)
        ax_l.step(agg["env_steps"], agg["curriculum_level"], where="post", **style)
    ax_r.set_ylabel("mean episode reward\n(last 20 episodes per env)")
    ax_s.set_ylabel("success rate\n(last 20 episodes per env)")
    ax_s.set_ylim(-0.03, 1.03)
    ax_l.set_ylabel("curriculum level\n(cm or deg)")
    ax_l.set_xlabel("env steps" if max_env_steps is None else f"env steps (first {max_env_steps:,} of every run)")
    if max_env_steps is not None:
        ax_l.set_xlim(0, max_env_steps)
    # the legend goes under the panels, as tall as its (wrapped) lines: run labels name whole recipes
    legend_in = LEGEND_LINE_IN * sum(label.count("\n") + 1 for label in labels) + 0.2
    width_in, height_in = fig.get_size_inches()
    fig.set_size_inches(width_in, height_in + legend_in)
    fig.legend(*ax_r.get_legend_handles_labels(), loc="lower left", fontsize=7, frameon=False)  # one entry per run
    ax_r.grid(alpha=0.3)
    ax_s.grid(alpha=0.3)
    ax_l.grid(alpha=0.3)
    fig.suptitle(title or "hexbench learning curves")
    fig.tight_layout(rect=(0, legend_in / (height_in + legend_in), 1, 1))
    out_png = save_png(fig, out_png)
    written = [out_png]
    if copy_csv:
        for source, (_agg, _label, run) in zip(sources, loaded):
            source = Path(source)
            if source.is_dir() and run:
                stem = source.resolve().name  # the run directory's name: unique, unlike method-terrain-seed
                dest = out_png.parent / f"{stem}.csv"
                shutil.copyfile(source / "progress.csv", dest)
                summary = {k: run.get(k) for k in ("method", "terrain", "seed", "workers", "total_steps", "env_steps",
                                                   "wall_time_s", "started_utc", "hexbench_commit", "config",
                                                   "init_from", *TRAINING_OPTION_KEYS)}
                summary["command"] = run["sessions"][0]["command"] if run.get("sessions") else run.get("command")
                summary["partial"] = run.get("env_steps", 0) < run.get("total_steps", 0)
                side = dest.with_suffix(".run.json")
                write_json_atomic(side, summary)
                written += [dest, side]
    return written


BAND_PANELS: tuple[tuple[str, str], ...] = (
    ("mean_episode_reward", "mean episode reward\n(last 20 episodes per env)"),
    ("success_rate", "success rate\n(last 20 episodes per env)"),
    ("curriculum_level", "curriculum level\n(cm or deg)"),
)


def seed_band(values, confidence: float = 0.95):
    """(mean, low, high) over seeds (rows) at each grid point (columns), NaN where a run has no data;
    the interval is Student's t over the seeds present there (none with a single seed)."""
    import numpy as np
    from scipy import stats

    values = np.asarray(values, dtype=float)
    present = np.isfinite(values)
    n = present.sum(axis=0)
    filled = np.where(present, values, 0.0)
    mean = np.where(n > 0, filled.sum(axis=0) / np.maximum(n, 1), np.nan)
    squares = np.where(present, (values - mean) ** 2, 0.0).sum(axis=0)
    sd = np.sqrt(squares / np.maximum(n - 1, 1))
    half = np.where(n > 1, stats.t.ppf(0.5 + confidence / 2, np.maximum(n - 1, 1)) * sd / np.sqrt(np.maximum(n, 1)),
                    np.nan)
    return mean, mean - half, mean + half


def plot_bands(sources: list[Path], out_png: Path, title: str = "", max_env_steps: int | None = None,
               grid_points: int = 201) -> list[Path]:
    """Paper Fig. 4 over seeds: per method and recipe, the mean over its seeds of reward, success rate
    and curriculum level, with a 95% band (Student's t over seeds), against env steps.

    Runs are grouped as `line_styles` groups them (method and recipe; seeds apart), so a source needs
    its run.json (a run directory, or a CSV with its .run.json beside it). Each run is interpolated
    onto a common env-step grid within the steps it logged, never beyond: a shorter run leaves the
    mean to the others there. Legends name methods, recipes and seeds, never run directories.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    if not sources:
        raise CurvesError("no runs given; pass run directories (training/...) or progress CSVs with their .run.json")
    if max_env_steps is not None and max_env_steps <= 0:
        raise CurvesError(f"--max-env-steps must be a positive number of env steps, got {max_env_steps}")
    groups: dict[tuple[str, str], list[tuple[pd.DataFrame, dict]]] = {}
    for source in sources:
        agg, _label, run = load_progress(Path(source), max_env_steps)
        if not run or not run.get("method"):
            raise CurvesError(f"{source}: no run.json beside its progress CSV; --bands groups runs by the method "
                              "and recipe in it")
        if len(agg) == 0:
            raise CurvesError(f"{source}: no progress rows" + (f" within {max_env_steps:,} env steps"
                                                                if max_env_steps else ""))
        groups.setdefault(recipe_key(run["method"], run), []).append((agg, run))
    budget = max_env_steps or max(int(run.get("total_steps") or agg["env_steps"].max())
                                  for members in groups.values() for agg, run in members)
    grid = np.linspace(0, budget, grid_points)
    fig, axes = plt.subplots(3, 1, figsize=(9, 10.5), sharex=True, height_ratios=(3, 2, 2))
    styles = line_styles([key[:1] + (members[0][1],) for key, members in groups.items()])
    for (key, members), style in zip(groups.items(), styles):
        method, run0 = key[0], members[0][1]
        seeds = sorted(run.get("seed") for _agg, run in members if run.get("seed") is not None)
        label = f"{method}{recipe_description(run0)}: " + (
            f"mean of {len(members)} seeds ({', '.join(str(s) for s in seeds)}), 95% band"
            if len(members) > 1 else f"1 seed ({', '.join(str(s) for s in seeds)}), no band")
        label = "\n".join(textwrap.wrap(label, LEGEND_LINE_CHARS))
        for ax, (column, _ylabel) in zip(axes, BAND_PANELS):
            values = np.array([np.where((grid >= agg["env_steps"].min()) & (grid <= agg["env_steps"].max()),
                                        np.interp(grid, agg["env_steps"], agg[column]), np.nan)
                               for agg, _run in members])
            mean, low, high = seed_band(values)
            ax.plot(grid, mean, color=style["color"], lw=1.8, label=label)
            ax.fill_between(grid, low, high, color=style["color"], alpha=0.2, lw=0)
    for ax, (_column, ylabel) in zip(axes, BAND_PANELS):
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[1].set_ylim(-0.03, 1.03)
    axes[2].set_xlabel("env steps")
    axes[2].set_xlim(0, budget)
    labels = axes[0].get_legend_handles_labels()[1]
    legend_in = LEGEND_LINE_IN * sum(label.count("\n") + 1 for label in labels) + 0.2
    width_in, height_in = fig.get_size_inches()
    fig.set_size_inches(width_in, height_in + legend_in)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower left", fontsize=7, frameon=False)
    fig.suptitle(title or "hexbench learning curves: mean over seeds, 95% band (Student's t)")
    fig.tight_layout(rect=(0, legend_in / (height_in + legend_in), 1, 1))
    return [save_png(fig, out_png)]
