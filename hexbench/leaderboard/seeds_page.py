"""leaderboard/seeds/: the methods across their seeds (README.md and one figure per terrain).

Per terrain: the IQM of success per level with its 95% band and the performance profile (one SVG,
deterministic bytes), the methods' aggregates, PPO-CPG's probability of improvement over every
other method, and every seed run's own row. Strings from records go through md_text/md_code.
"""

from __future__ import annotations

import io

from hexbench.leaderboard import seeds as seed_runs
from hexbench.leaderboard.formatting import TERRAIN_AXES, TERRAIN_TITLES, fmt_level, fmt_num, fmt_trust, one_line
from hexbench.leaderboard.markdown import md_table, md_text
from hexbench.leaderboard.plots import MEASURED_COLORS, literal_legend_texts
from hexbench.leaderboard.statistics import DEFAULT_RESAMPLES, Estimate
from hexbench.suite import scoring
from hexbench.suite.tasks import Suite, format_level

SEEDS_PAGE_DIR = "seeds"  # under the leaderboard folder
# the untrained references: greys and dashes of their own, in seed_runs.REFERENCE_METHODS order
REFERENCE_STYLES = (("#555555", (0, (4, 2))), ("#999999", (0, (1, 1.5))))


def figure_name(terrain: str) -> str:
    return f"{terrain}.svg"


def fmt_estimate(e: Estimate, digits: int = 2, percent: bool = False) -> str:
    """`value (low–high)`; a single run has no interval: `value (1 run)`."""
    scale, unit = (100, "%") if percent else (1, "")
    point = f"{scale * e.value:.{0 if percent else digits}f}{unit}"
    if e.n_runs < 2 and e.low == e.high:
        return f"{point} (1 run)"
    return f"{point} ({scale * e.low:.{0 if percent else digits}f}–{scale * e.high:.{0 if percent else digits}f})"


def _unit(suite: Suite, terrain: str) -> str:
    return suite.task(terrain, suite.levels(terrain)[0]).unit


def _styles(aggregates: list[seed_runs.TerrainAggregate]) -> dict[seed_runs.Method, tuple[str, object]]:
    """One (colour, line style) per method, shared by every terrain's figure: trained methods solid in
    colour, each untrained reference a grey and dash of its own."""
    methods = list(dict.fromkeys(a.method for a in aggregates))
    trained = [m for m in methods if m.budget_env_steps is not None]
    styles = {m: (MEASURED_COLORS[i % len(MEASURED_COLORS)], "-") for i, m in enumerate(trained)}
    references = sorted((m for m in methods if m.budget_env_steps is None),
                        key=lambda m: seed_runs.REFERENCE_METHODS.index(m.label))
    styles.update({m: REFERENCE_STYLES[i % len(REFERENCE_STYLES)] for i, m in enumerate(references)})
    return styles


def figure_svg(aggregates: list[seed_runs.TerrainAggregate], terrain: str, suite: Suite,
               styles: dict[seed_runs.Method, tuple[str, object]]) -> str:
    """IQM of success per level with its 95% band (left) and the performance profile (right)."""
    import matplotlib
    from matplotlib.figure import Figure

    shown = [a for a in aggregates if a.terrain == terrain]
    unit = _unit(suite, terrain)
    taus = seed_runs.profile_thresholds()
    with matplotlib.rc_context({"svg.hashsalt": f"hexbench-seeds-{terrain}", "svg.fonttype": "none",
                                "font.family": "DejaVu Sans", "font.size": 9,
                                "axes.spines.top": False, "axes.spines.right": False}):
        fig = Figure(figsize=(9.6, 3.7))
        left = fig.add_axes((0.07, 0.14, 0.36, 0.72))
        right = fig.add_axes((0.51, 0.14, 0.2, 0.72))
        for a in shown:
            color, style = styles[a.method]
            label = one_line(f"{a.method.name}, {len(a.runs)} run{'s' if len(a.runs) != 1 else ''}")
            x = list(a.levels)
            left.plot(x, [e.value for e in a.per_level], color=color, ls=style, lw=1.8, marker="o", ms=3.5,
                      label=label, zorder=3)
            if len(a.runs) > 1:
                left.fill_between(x, [e.low for e in a.per_level], [e.high for e in a.per_level], color=color,
                                  alpha=0.18, lw=0, zorder=2)
            profile = [float(v) for v in seed_runs.statistics.performance_profile(a.scores, taus)]
            right.step(taus, profile, where="post", color=color, ls=style, lw=1.6, zorder=3)
        left.axhline(scoring.PASS_THRESHOLD, color="#999999", lw=0.8, ls=(0, (2, 2)), zorder=1)
        left.set_xlabel(f"{TERRAIN_AXES.get(terrain, 'level')} [{unit}]")
        left.set_ylabel("success rate (IQM over runs)")
        left.set_title(f"{TERRAIN_TITLES.get(terrain, terrain)}: success per level, 95% band", fontsize=9)
        right.set_xlabel("success rate tau")
        right.set_ylabel("fraction of run x level scores > tau")
        right.set_title("performance profile", fontsize=9)
        for ax in (left, right):
            ax.set_ylim(-0.02, 1.04)
            ax.grid(axis="y", color="#e6e6e6", lw=0.6, zorder=0)
        legend = fig.legend(loc="upper left", bbox_to_anchor=(0.735, 0.86), frameon=False, fontsize=7.5,
                            title="method (recipe @ budget)", title_fontsize=8, handlelength=2.6)
        literal_legend_texts(legend)
        buf = io.StringIO()
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None, "Format": None, "Type": None})
    return buf.getvalue()


def _methods_table(shown: list[seed_runs.TerrainAggregate], unit: str) -> str:
    levels = shown[0].levels
    header = ["Method", "Runs (seeds)", "AUC, IQM (95% CI)", "Headroom AUC, IQM (95% CI)",
              "Success over the paper levels, IQM (95% CI)"] + [format_level(v) + f" {unit}" for v in levels]
    rows = []
    for a in shown:
        seeds = ", ".join(str(s) for s in a.seeds) if a.seeds else "one record"
        rows.append([md_text(a.method.name), f"{len(a.runs)} ({seeds})", fmt_estimate(a.auc),
                     "–" if a.headroom_auc is None else fmt_estimate(a.headroom_auc),
                     fmt_estimate(a.all_levels, percent=True)] + [fmt_estimate(e, percent=True) for e in a.per_level])
    return md_table(header, rows)


def _improvement_table(found: list[seed_runs.Improvement]) -> str:
    header = ["P(X > Y)", "Y", "value (95% CI)", "verdict"]
    rows = []
    for imp in found:
        e = imp.estimate
        verdict = ("X better" if e.low > 0.5 else "Y better" if e.high < 0.5 else "no clear difference")
        rows.append([f"X = {md_text(imp.better.name)}", md_text(imp.other.name), fmt_estimate(e), verdict])
    return md_table(header, rows, align=["l", "l", "r", "l"])


def _runs_table(shown: list[seed_runs.TerrainAggregate], terrain: str, unit: str) -> str:
    header = ["Method", "Seed", "Selected at [env steps]", "Hardest passed", "AUC", "Successes", "Trust", "Record"]
    rows = []
    for a in shown:
        for r in a.runs:
            t = r.row.terrain(terrain)
            folder = f"{r.folder}/result-{terrain}.json" if r.seed is not None else r.folder
            rows.append([md_text(a.method.name), "–" if r.seed is None else str(r.seed),
                         "–" if r.selected_env_steps is None else f"{r.selected_env_steps:,}",
                         fmt_level(t["hardest_level_passed"], unit), fmt_num(t["auc"], 3),
                         f"{t['successes']} of {t['episodes']}", fmt_trust(r.row), md_text(folder)])
    return md_table(header, rows, align=["l", "r", "r", "r", "r", "r", "l", "l"])


def _trained_on(aggregates: list[seed_runs.TerrainAggregate], terrain: str) -> bool:
    return any(a.terrain == terrain and a.method.budget_env_steps is not None for a in aggregates)


def render_seeds_page(aggregates: list[seed_runs.TerrainAggregate], found: list[seed_runs.Improvement],
                      suite: Suite, errors: list[str], unscored: list[str] = ()) -> dict[str, str]:
    """README.md and each terrain's figure, as {file name: text}."""
    styles = _styles(aggregates)
    out = [f"# hexbench across seeds: protocol {suite.protocol}\n",
           "Generated by `hexbench leaderboard build` from the seed runs in `baselines/seeds/` "
           "(baselines/seeds/README.md: each is one baseline recipe trained from scratch on one terrain by "
           "the documented command, its checkpoint selected on held-out episodes, then scored by "
           "`hexbench run FILE --terrain T`, 20 protocol episodes per level) and the full-run records of the "
           f"untrained references ({', '.join(f'`{m}`' for m in seed_runs.REFERENCE_METHODS)}: no training, one "
           "record each); do not edit by hand.\n",
           "A method is a baseline file's recipe at one env-step budget; methods at different budgets are "
           "not compared as like for like. Statistics follow rliable (Agarwal et al., NeurIPS 2021), computed "
           "with scipy: the interquartile mean (IQM) over runs, stratified-bootstrap 95% percentile intervals "
           f"({DEFAULT_RESAMPLES} resamples, generator seed {seed_runs.BOOTSTRAP_SEED}), performance profiles "
           "over the run x level success rates, and the probability of improvement P(X > Y) (Mann-Whitney, "
           "averaged over levels). Scores are success rates at the paper's levels (headroom levels left out, as "
           "in the AUC); the headroom AUC, the same area over the levels beyond the paper's, tells apart "
           "methods that every paper level saturates (slopes). With fewer than 4 runs the IQM is close to the "
           "mean and the interval is wide: read both with the number of runs beside them.\n"]
    if not any(_trained_on(aggregates, t) for t in suite.terrains):
        out.append("No seed runs yet.\n")
    for terrain in suite.terrains:
        shown = [a for a in aggregates if a.terrain == terrain]
        if not _trained_on(aggregates, terrain):
            continue  # the references alone: nothing across seeds to show
        unit = _unit(suite, terrain)
        out.append(f"## {TERRAIN_TITLES.get(terrain, terrain)}\n")
        out.append(f"![{TERRAIN_TITLES.get(terrain, terrain)}: IQM success per level with 95% bands, and "
                   f"performance profiles]({figure_name(terrain)})\n")
        out.append(_methods_table(shown, unit) + "\n")
        terrain_improvements = [i for i in found if i.terrain == terrain]
        if terrain_improvements:
            out.append("Probability of improvement (over the paper levels' success rates; a verdict only where "
                       "the 95% interval excludes 0.5):\n")
            out.append(_improvement_table(terrain_improvements) + "\n")
        out.append("Runs:\n")
        out.append(_runs_table(shown, terrain, unit) + "\n")
    if unscored:
        out.append("## Trained, not yet scored\n")
        out.append("Seed-run folders whose checkpoint is committed but whose `result-<terrain>.json` is not made yet "
                   "(they count once scored):\n")
        out += [f"- {md_text(name, block=True)}" for name in unscored]
        out.append("")
    if errors:
        out.append("## Refused seed runs\n")
        out += [f"- {md_text(e, block=True)}" for e in errors]
        out.append("")
    files = {"README.md": "\n".join(out)}
    for terrain in suite.terrains:
        if _trained_on(aggregates, terrain):
            files[figure_name(terrain)] = figure_svg(aggregates, terrain, suite, styles)
    return files
