"""leaderboard/index.html: the whole leaderboard as one self-contained page.

Sortable tables, the plots inline as SVG, the stylesheet and script inlined from
hexbench/leaderboard/assets/; nothing is fetched from elsewhere. Every string from a record goes
through `_e` (text and attribute values); only the page's own assets go inside <style> and <script>.
"""

from __future__ import annotations

import html
from pathlib import Path

from hexbench.leaderboard.budget import fmt_budget
from hexbench.leaderboard.formatting import (
    REPORTED_NOTE,
    TERRAIN_AXES,
    TERRAIN_TITLES,
    fmt_level,
    fmt_num,
    fmt_trust,
    pct,
)
from hexbench.leaderboard.plots import measured_color, plot_svg
from hexbench.leaderboard.ranking import RANKING_RULE, Board, overall_metrics
from hexbench.leaderboard.records import Row
from hexbench.suite.tasks import format_level

ASSETS_DIR = Path(__file__).parent / "assets"


def _e(text) -> str:
    """Text or an attribute value for the page (every string from a record goes through this)."""
    return html.escape(str(text), quote=True)


def _raw_text(text: str) -> str:
    """Contents of a <script> or <style> element: `</` escaped (`<\\/`, the same in JavaScript strings,
    JSON and CSS), so nothing inside can close the element. The page inlines only its own assets there,
    never record data."""
    return text.replace("</", "<\\/")


def _sort_attr(value) -> str:
    return "" if value is None else f' data-sort="{value!r}"' if isinstance(value, float) else f' data-sort="{_e(value)}"'


def _asset(name: str) -> str:
    return (ASSETS_DIR / name).read_text()


def generator_tag() -> str:
    """Names the plotting library version: SVG bytes are reproducible for one matplotlib version."""
    import matplotlib

    return f"hexbench leaderboard build; matplotlib {matplotlib.__version__}"


# ---------------------------------------------------------------------------------- tables
def _summary_head(board: Board, ranked: bool) -> list[str]:
    head = ['<th data-type="num" title="overall rank (see the ranking rule)">Rank</th>' if ranked else "",
            '<th data-type="text">Controller</th>']
    if not ranked:
        head.append('<th data-type="text">Setting</th>')
    else:
        head.append('<th data-type="num" title="stated env-step budget of the shipped weights (checkpoint manifest)">'
                    'Training<br><span class="sub">env steps</span></th>')
    for t in board.suite.terrains:
        name = TERRAIN_TITLES.get(t, t)
        head.append(f'<th data-type="num" title="hardest level with success rate &gt;= 80%">{_e(name)}<br>'
                    '<span class="sub">hardest passed</span></th>')
        head.append(f'<th data-type="num" title="area under the success-vs-level curve (paper levels)">{_e(name)}<br>'
                    '<span class="sub">AUC</span></th>')
    if ranked:
        head += ['<th data-type="num">Speed<br><span class="sub">m/s</span></th>',
                 '<th data-type="num">Roll RMS<br><span class="sub">deg</span></th>',
                 '<th data-type="num">Pitch RMS<br><span class="sub">deg</span></th>',
                 '<th data-type="num">Episodes</th>']
    return head


def _summary_name_cells(board: Board, r: Row, ranked: bool) -> list[str]:
    if not ranked:
        return [f'<td class="name"{_sort_attr(r.label)}>{_e(r.label)}<span class="badge">paper</span></td>',
                f'<td{_sort_attr(r.setting)}>{_e(r.setting)}</td>']
    rank = board.overall_ranks[r.label]
    training = board.training.get(r.label)
    budget = max(training.budgets) if training is not None and training.known and training.budgets else -1.0
    return [f'<td class="num rank"{_sort_attr(float(rank))}>{rank}</td>',
            f'<td class="name"{_sort_attr(r.label)}><span class="swatch" style="background:'
            f'{measured_color(board, r.label)}"></span>{_e(r.label)}'
            f'<span class="mode">{_e(r.details.get("action_mode", ""))}</span></td>',
            f'<td class="num"{_sort_attr(float(budget))}>{_e(fmt_budget(training))}</td>']


def _summary_row(board: Board, r: Row, ranked: bool) -> str:
    cells = _summary_name_cells(board, r, ranked)
    for t in board.suite.terrains:
        s = r.terrain(t)
        if s is None:
            cells += ['<td class="num na">–</td>', '<td class="num na">–</td>']
            continue
        hardest, auc = s["hardest_level_passed"], s["auc"]
        cells.append(f'<td class="num"{_sort_attr(-1.0 if hardest is None else float(hardest))}>'
                     f'{_e(fmt_level(hardest, s["unit"]))}</td>')
        cells.append(f'<td class="num"{_sort_attr(-1.0 if auc is None else float(auc))}>{fmt_num(auc)}</td>')
    if ranked:
        m = overall_metrics(r)
        for key, digits in (("mean_forward_speed_m_per_s", 3), ("mean_roll_rms_deg", 1),
                            ("mean_pitch_rms_deg", 1)):
            v = m[key]
            cells.append(f'<td class="num"{_sort_attr(-1.0 if v is None else float(v))}>{fmt_num(v, digits)}</td>')
        cells.append(f'<td class="num"{_sort_attr(float(m["episodes"]))}>{m["episodes"]}</td>')
    row_class = "measured" if ranked else "reported"
    return f'<tr class="{row_class}" data-label="{_e(r.label)}">' + "".join(cells) + "</tr>"


def _summary_table(board: Board, rows: list[Row], table_id: str, ranked: bool) -> str:
    head = _summary_head(board, ranked)
    body = [_summary_row(board, r, ranked) for r in rows]
    return (f'<table id="{table_id}" class="sortable"><thead><tr>{"".join(head)}</tr></thead>\n<tbody>\n'
            + "\n".join(body) + "\n</tbody></table>")


def _heat(rate: float) -> str:
    """Cell background: pale red (0%) to pale green (100%)."""
    hue = 8 + 112 * rate
    return f"hsl({hue:.0f}, 60%, 92%)"


def _level_cell(r: Row, lv: dict | None, cls: str) -> str:
    if lv is None:
        return f'<td class="{cls} na">–</td>'
    measured = r.kind == "measured"
    ci = (f'<span class="ci">{100 * lv["ci95_low"]:.0f}–{100 * lv["ci95_high"]:.0f}</span>'
          if measured else "")
    title = (f'{lv["successes"]}/{lv["episodes"]} episodes; 95% Wilson interval '
             f'{100 * lv["ci95_low"]:.0f}–{100 * lv["ci95_high"]:.0f}%' if measured
             else f'reported by the paper ({r.details["table"]}), not run here')
    return (f'<td class="{cls}" style="background:{_heat(lv["success_rate"])}" title="{_e(title)}">'
            f'{pct(lv["success_rate"])}{ci}</td>')


def _level_table(board: Board, terrain: str) -> str:
    suite = board.suite
    levels = suite.levels(terrain)
    paper_levels = set(suite.levels(terrain, include_headroom=False))
    unit = suite.task(terrain, levels[0]).unit
    head = [f'<th class="corner">level [{_e(unit)}]</th>']
    head += [f'<th class="num{"" if v in paper_levels else " headroom"}">{format_level(v)}</th>' for v in levels]
    body = []
    for r in (*board.measured, *(r for r in board.reported if r.setting == "simulation" and r.terrain(terrain))):
        measured = r.kind == "measured"
        name = (f'<span class="swatch" style="background:{measured_color(board, r.label)}"></span>{_e(r.label)}'
                if measured else f'{_e(r.label)}<span class="badge">paper</span>')
        cells = [f'<th class="rowname">{name}</th>']
        cells += [_level_cell(r, r.level(terrain, v), "num" + ("" if v in paper_levels else " headroom"))
                  for v in levels]
        body.append(f'<tr class="{"measured" if measured else "reported"}">' + "".join(cells) + "</tr>")
    return ('<table class="levels"><thead><tr>' + "".join(head) + "</tr></thead>\n<tbody>\n" + "\n".join(body)
            + "\n</tbody></table>")


def _real_robot_tables(board: Board) -> str:
    parts = []
    for r in (r for r in board.reported if r.setting == "real robot"):
        for t in r.terrains:
            lvs = [lv for lv in r.levels if lv["terrain"] == t["terrain"]]
            head = [f'<th class="corner">{_e(TERRAIN_TITLES.get(t["terrain"], t["terrain"]))} [{_e(t["unit"])}]</th>']
            head += [f'<th class="num">{format_level(lv["level"])}</th>' for lv in lvs]
            cells = [f'<th class="rowname">{_e(r.label)}<span class="badge">paper</span></th>']
            cells += [f'<td class="num" style="background:{_heat(lv["success_rate"])}">{pct(lv["success_rate"])}</td>'
                      for lv in lvs]
            parts.append('<table class="levels"><thead><tr>' + "".join(head) + '</tr></thead><tbody><tr class="reported">'
                         + "".join(cells) + "</tr></tbody></table>")
    return "\n".join(parts)


# ---------------------------------------------------------------------------------- sections
def _head(board: Board) -> list[str]:
    title = f"hexbench leaderboard: protocol {board.protocol}"
    return ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f'<meta name="generator" content="{_e(generator_tag())}">', f"<title>{_e(title)}</title>",
            "<style>", _raw_text(_asset("style.css").strip()), "</style>", "</head>", "<body>", "<main>",
            f'<header><h1>hexbench leaderboard <span class="proto">protocol {_e(board.protocol)}</span></h1>'
            f'<p class="lead">Hexapod locomotion on rough terrain, slopes and stairs: success over 20 seeded '
            f'episodes per difficulty level. {len(board.measured)} measured '
            f'{"entry" if len(board.measured) == 1 else "entries"}; the paper\'s own numbers are drawn as a '
            f'reference, <strong>{REPORTED_NOTE}</strong>. Click a column header to sort.</p></header>']


def _ranking(board: Board) -> list[str]:
    out = ['<section id="ranking"><h2>Ranking</h2>']
    if board.measured:
        out.append(_summary_table(board, list(board.measured), "leaderboard", ranked=True))
    else:
        out.append('<p class="empty">No measured records yet.</p>'
                   '<table id="leaderboard" class="sortable"><thead><tr><th>Controller</th></tr></thead>'
                   "<tbody></tbody></table>")
    out.append(f'<p class="rule"><strong>Ranking rule.</strong> {_e(RANKING_RULE)}</p></section>')
    if board.reported:
        out.append(f'<section id="paper-reference" class="reference"><h2>Paper reference <span class="note">'
                   f'{REPORTED_NOTE}</span></h2>')
        out.append(_summary_table(board, list(board.reported), "paper", ranked=False))
        for citation, note in board.reported_notes:
            out.append(f'<p class="cite">{_e(citation)}</p><p class="cite">{_e(note)}</p>')
        out.append("</section>")
    return out


def _terrain(board: Board, terrain: str) -> list[str]:
    return [f'<section class="terrain" id="terrain-{_e(terrain)}"><h2>{_e(TERRAIN_TITLES.get(terrain, terrain))}'
            "</h2>",
            f'<figure class="plot" data-terrain="{_e(terrain)}">{plot_svg(board, terrain).strip()}'
            f"<figcaption>Success rate vs {_e(TERRAIN_AXES.get(terrain, 'level'))}. Solid lines: measured here "
            "(whiskers: 95% Wilson interval). Dashed grey/black lines: the paper's Table 4 (and Table 6, real "
            f"robot), {REPORTED_NOTE}. The tinted band holds the headroom levels beyond the paper."
            "</figcaption></figure>",
            _level_table(board, terrain),
            "</section>"]


def _real_robot(board: Board) -> list[str]:
    if not any(r.setting == "real robot" for r in board.reported):
        return []
    return [f'<section id="real-robot" class="reference"><h2>Real robot <span class="note">{REPORTED_NOTE}'
            "</span></h2>", _real_robot_tables(board), "</section>"]


def _records(board: Board) -> list[str]:
    if not board.measured:
        return []
    out = ['<section id="records"><h2>Records</h2><table class="records"><thead><tr><th>Controller</th>'
           "<th>Trust</th><th>Record</th><th>Controller file</th><th>sha256</th><th>git commit</th><th>Episodes</th>"
           "<th>Wall time</th><th>Command</th></tr></thead><tbody>"]
    for r in board.measured:
        d = r.details
        out.append(f"<tr><td>{_e(r.label)}</td><td>{_e(fmt_trust(r))}</td><td>{_e(r.source)}</td>"
                   f"<td><code>{_e(d['controller_file'])}</code>"
                   f"</td><td><code title=\"{_e(d['controller_sha256'])}\">{_e(d['controller_sha256'][:12])}</code>"
                   f"</td><td><code>{_e(str(d['git_commit'])[:12])}</code></td><td>{d['episodes']}</td>"
                   f"<td>{d['wall_time_s']:.0f} s</td><td><code>{_e(d['command'])}</code></td></tr>")
    out.append("</tbody></table></section>")
    return out


def _foot() -> list[str]:
    return ['<footer>Generated by <code>hexbench leaderboard build</code> from the records in this folder '
            "(never edited by hand). Success: the base advances 2.5 m along +x without falling and without "
            "straying more than 0.8 m sideways. Summaries are recomputed from each record's per-episode rows. "
            "Every number is also in <code>leaderboard.csv</code>.</footer>",
            "</main>", "<script>", _raw_text(_asset("sortable.js").strip()), "</script>", "</body>", "</html>"]


def render_html(board: Board) -> str:
    out = _head(board) + _ranking(board)
    for terrain in board.suite.terrains:
        out += _terrain(board, terrain)
    out += _real_robot(board) + _records(board) + _foot()
    return "\n".join(out) + "\n"
