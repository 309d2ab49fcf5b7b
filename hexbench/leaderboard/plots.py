"""The success-vs-level plot of each terrain as inline SVG, with deterministic bytes.

Measured entries are solid lines with their 95% Wilson whiskers, the paper's series dashed grey and
black, the headroom levels on a tinted band. matplotlib writes the SVG with a fixed hash salt and no
date; legend entries (record labels) are literal text, never mathtext.
"""

from __future__ import annotations

import io
import re

from hexbench.leaderboard.formatting import REPORTED_NOTE, TERRAIN_AXES, TERRAIN_TITLES, one_line
from hexbench.leaderboard.ranking import Board
from hexbench.suite import scoring

MEASURED_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2",
                   "#bcbd22", "#7f7f7f")
REPORTED_STYLES = (("#555555", (0, (5, 3)), "s"), ("#555555", (0, (6, 2, 1, 2)), "^"), ("#000000", (0, (3, 2)), "D"),
                   ("#000000", (0, (1, 1.5)), "x"), ("#888888", (0, (4, 1, 1, 1, 1, 1)), "v"))


def measured_color(board: Board, label: str) -> str:
    """A fixed colour per measured controller (by overall order), shared by plots and tables."""
    labels = [r.label for r in board.measured]
    return MEASURED_COLORS[labels.index(label) % len(MEASURED_COLORS)]


def literal_legend_texts(legend) -> None:
    """Legend entries are record labels: drawn as literal text, never parsed as mathtext (`$...$`).
    matplotlib escapes text for SVG itself (`<`, `&`; `--` in the comments it writes)."""
    for text in legend.get_texts():
        text.set_parse_math(False)


def _draw_guides(ax, levels_all: list[float], paper_levels: list[float], x_max: float) -> None:
    """The headroom band and the pass line."""
    extra = [v for v in levels_all if v not in paper_levels]
    if extra:  # the headroom band starts half-way between the last paper level and the first extra one
        band_start = (max(paper_levels) + min(extra)) / 2
        ax.axvspan(band_start, x_max, color="#f3efe2", zorder=0, lw=0)
        ax.text((band_start + x_max) / 2, 1.075, "headroom (beyond the paper)", ha="center", va="bottom",
                fontsize=7.5, color="#8a7a4a", clip_on=False)
    ax.axhline(scoring.PASS_THRESHOLD, color="#999999", lw=0.8, ls=(0, (2, 2)), zorder=1)
    ax.text(min(levels_all) - 0.2, scoring.PASS_THRESHOLD - 0.015, "pass (80%)", fontsize=7.5, color="#777777",
            va="top")


def _draw_reported(ax, board: Board, terrain: str) -> list:
    handles = []
    for i, r in enumerate(r for r in board.reported if r.terrain(terrain)):
        color, style, marker = REPORTED_STYLES[i % len(REPORTED_STYLES)]
        pts = [lv for lv in r.levels if lv["terrain"] == terrain]
        (line,) = ax.plot([p["level"] for p in pts], [p["success_rate"] for p in pts], color=color, ls=style,
                          lw=1.3, marker=marker, ms=4.5, mfc="white", mew=1.1, zorder=2, label=one_line(r.label))
        handles.append(line)
    return handles


def _draw_measured(ax, board: Board, terrain: str, levels_all: list[float]) -> list:
    gaps = [b - a for a, b in zip(levels_all, levels_all[1:])]
    dodge = 0.08 * min(gaps) if gaps else 0.0  # side-by-side whiskers so intervals stay readable
    n_measured = len(board.measured)
    handles = []
    for i, r in enumerate(board.measured):
        pts = [lv for lv in r.levels if lv["terrain"] == terrain]
        color = measured_color(board, r.label)
        x = [p["level"] + (i - (n_measured - 1) / 2) * dodge for p in pts]
        y = [p["success_rate"] for p in pts]
        yerr = [[v - p["ci95_low"] for v, p in zip(y, pts)], [p["ci95_high"] - v for v, p in zip(y, pts)]]
        container = ax.errorbar(x, y, yerr=yerr, color=color, lw=2.0, marker="o", ms=4.5, zorder=4,
                                elinewidth=1.0, capsize=2.0, capthick=1.0, ecolor=color, label=one_line(r.label))
        for bar in container[2]:
            bar.set_alpha(0.55)
        handles.append(container)
    return handles


def _draw_axes(ax, levels_all: list[float], x_max: float, terrain: str, unit: str) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlim(min(levels_all) - 0.25, x_max)
    ax.set_ylim(-0.02, 1.04)
    ax.set_yticks([0, 0.2, 0.4, 0.6, 0.8, 1.0], ["0%", "20%", "40%", "60%", "80%", "100%"])
    ax.set_xlabel(f"{TERRAIN_AXES.get(terrain, 'level')} [{unit}]")
    ax.set_ylabel("success rate")
    ax.grid(axis="y", color="#e6e6e6", lw=0.6, zorder=0)


def _draw_legends(fig, measured_handles: list, reported_handles: list) -> None:
    legend_style = {"loc": "upper left", "frameon": False, "fontsize": 7.5, "title_fontsize": 8,
                    "handlelength": 2.8, "alignment": "left"}
    top = 0.95
    if measured_handles:
        legend = fig.legend(handles=measured_handles, title="measured here\n(whiskers: 95% Wilson interval)",
                            bbox_to_anchor=(0.655, top), **legend_style)
        legend.get_title().set_fontweight("bold")
        literal_legend_texts(legend)
        top -= 0.062 * (len(measured_handles) + 2) + 0.05
    if reported_handles:
        legend = fig.legend(handles=reported_handles, title=f"paper reference\n({REPORTED_NOTE})",
                            bbox_to_anchor=(0.655, top), **legend_style)
        legend.get_title().set_fontweight("bold")
        legend.get_title().set_color("#6b5b2e")
        literal_legend_texts(legend)


def _inline_svg(svg: str, terrain: str) -> str:
    """matplotlib's SVG made fit to sit in a page beside the other terrains' plots."""
    svg = svg[svg.index("<svg"):]  # drop the XML declaration and DOCTYPE for inlining in HTML
    svg = re.sub(r'<svg([^>]*?) width="[^"]+" height="[^"]+"', r'<svg\1', svg, count=1)
    # Three plots share one page: prefix every element id (and its references) with the terrain.
    # Inside tags only: text (legend entries are record labels) is left exactly as it is; matplotlib
    # escapes `<` and `>` in it, so no text is taken for a tag.
    tag_re = re.compile(r"<(?!!--)[^<>]*>")
    ids = {i for tag in tag_re.findall(svg) for i in re.findall(r'\bid="([^"]+)"', tag)} - {f"plot-{terrain}"}

    def prefix_ids(tag: re.Match) -> str:
        t = re.sub(r'\bid="([^"]+)"', lambda m: f'id="{terrain}-{m.group(1)}"' if m.group(1) in ids else m.group(0),
                   tag.group(0))
        return re.sub(r'(url\(#|href="#)([^)"]+)', lambda m: f"{m.group(1)}{terrain}-{m.group(2)}"
                      if m.group(2) in ids else m.group(0), t)

    svg = tag_re.sub(prefix_ids, svg)
    svg = svg.replace("<svg", f'<svg role="img" aria-label="{TERRAIN_TITLES.get(terrain, terrain)}: success rate '
                      'versus level"', 1)
    return svg.strip() + "\n"


def plot_svg(board: Board, terrain: str) -> str:
    """Success vs level for one terrain as an SVG string (deterministic bytes)."""
    import matplotlib
    from matplotlib.figure import Figure

    suite = board.suite
    unit = suite.task(terrain, suite.levels(terrain)[0]).unit
    levels_all = suite.levels(terrain)
    paper_levels = suite.levels(terrain, include_headroom=False)
    with matplotlib.rc_context({"svg.hashsalt": f"hexbench-leaderboard-{terrain}", "svg.fonttype": "none",
                                "svg.id": f"plot-{terrain}", "font.family": "DejaVu Sans", "font.size": 9,
                                "axes.spines.top": False, "axes.spines.right": False}):
        fig = Figure(figsize=(8.4, 3.6))
        ax = fig.add_axes((0.075, 0.14, 0.55, 0.78))
        x_max = max(levels_all) + 0.25
        _draw_guides(ax, levels_all, paper_levels, x_max)
        reported_handles = _draw_reported(ax, board, terrain)
        measured_handles = _draw_measured(ax, board, terrain, levels_all)
        _draw_axes(ax, levels_all, x_max, terrain, unit)
        _draw_legends(fig, measured_handles, reported_handles)
        buf = io.StringIO()
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None, "Format": None, "Type": None})
    return _inline_svg(buf.getvalue(), terrain)
