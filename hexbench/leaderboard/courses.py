"""The extra courses (the mixed course): records in `leaderboard/courses/`, scored apart.

Their records are validated like full-run records, against the levels and seeds of the courses they
cover, and render `leaderboard/courses/README.md`; they are never ranked with the full run. The same
page shows paper Table 5 on its own tasks: records in `leaderboard/courses/table5/` of the rough
terrain model on the slopes and stairs levels of Table 5, beside the paper's row.
"""

from __future__ import annotations

from pathlib import Path

from hexbench.leaderboard.formatting import fmt_num, fmt_trust
from hexbench.leaderboard.markdown import md_code, md_success_cell, md_table, md_text
from hexbench.leaderboard.records import EpisodeClaims, LoadResult, RecordError, Row, measured_row, read_record, record_files
from hexbench.suite.tasks import DEFAULT_PROTOCOL, Suite, format_level, load_suite

COURSES_DIR = "courses"  # records of the extra courses (the mixed course), scored apart
TABLE5_DIR = "table5"  # under COURSES_DIR: records of the rough terrain model on slopes and stairs
# Paper Table 5 ("Success Rates of Our Method in Slopes and Stairs with Rough Terrain's model"),
# transcribed: level -> success rate, 20 trials each (section 4.4)
PAPER_TABLE_5: dict[str, dict[float, float]] = {
    "slopes": {10: 1.0, 11: 1.0, 12: 1.0, 13: 1.0, 14: 0.4, 15: 0.0},
    "stairs": {5.5: 1.0, 6: 0.7, 6.5: 0.3, 7: 0.0, 7.5: 0.0, 8: 0.0},
}


def is_course_record(record: dict) -> bool:
    """A measured record whose episodes all lie on extra courses (not the full run)."""
    try:
        suite = load_suite(record["protocol"])
        terrains = {e["terrain"] for e in record["episodes"]}
    except (KeyError, TypeError, ValueError):
        return False
    return bool(terrains) and terrains <= set(suite.extra_terrains)


def load_course_rows(directory: Path, protocol: str = DEFAULT_PROTOCOL, claims: EpisodeClaims | None = None) -> LoadResult:
    result = LoadResult([], [], [])
    claims = EpisodeClaims() if claims is None else claims
    for path in record_files(directory):
        try:
            record = read_record(path)
            if record.get("protocol") != protocol:
                result.skipped.append(f"{path}: protocol {record.get('protocol')!r}, not {protocol!r}")
                continue
            row = measured_row(record, str(path), course=True)
            claims.claim(record, str(path))
            result.rows.append(row)
        except RecordError as e:
            result.errors.append(str(e))
    return result


def table5_tasks_text() -> str:
    """Table 5's tasks as one line: 'slopes 10, 11, ...; stairs 5.5, 6, ...'."""
    return "; ".join(f"{t} {', '.join(format_level(v) for v in levels)}" for t, levels in PAPER_TABLE_5.items())


def is_table5_record(record: dict) -> bool:
    """A measured record whose episodes all lie on paper Table 5's tasks (some slopes and stairs levels)."""
    try:
        tasks = {(e["terrain"], float(e["level"])) for e in record["episodes"]}
    except (KeyError, TypeError, ValueError):
        return False
    return record.get("kind") == "measured" and bool(tasks) \
        and all(level in PAPER_TABLE_5.get(terrain, {}) for terrain, level in tasks)


def table5_row(record: dict, where: str) -> Row:
    """The row of a record of Table 5's tasks (every seed of each level it covers); RecordError if refused."""
    row = measured_row(record, where, levels_covered=True)
    outside = sorted({f"{lv['terrain']} {format_level(lv['level'])}" for lv in row.levels
                      if lv["level"] not in PAPER_TABLE_5.get(lv["terrain"], {})})
    if outside:
        raise RecordError(f"{where}: {', '.join(outside)} is not a paper Table 5 task; valid: {table5_tasks_text()}")
    return row


def table5_file_name(label_slug: str, row: Row) -> str:
    """`<label>-<terrain>[-<terrain>].json`: one file per controller and terrains covered."""
    return f"{label_slug}-{'-'.join(sorted({t['terrain'] for t in row.terrains}))}.json"


def load_table5_rows(directory: Path, protocol: str = DEFAULT_PROTOCOL, claims: EpisodeClaims | None = None) -> LoadResult:
    """Records of Table 5's tasks: some levels of slopes and stairs, every seed of each level."""
    result = LoadResult([], [], [])
    claims = EpisodeClaims() if claims is None else claims
    for path in record_files(directory):
        try:
            record = read_record(path)
            if record.get("protocol") != protocol:
                result.skipped.append(f"{path}: protocol {record.get('protocol')!r}, not {protocol!r}")
                continue
            row = table5_row(record, str(path))
            claims.claim(record, str(path))
            result.rows.append(row)
        except RecordError as e:
            result.errors.append(str(e))
    return result


TABLE5_CONTEXT = ("cpg", "ppo_cpg")  # full-run entries shown on Table 5's tasks for comparison


def _table5_section(rows: list[Row], suite: Suite, context: list[Row]) -> list[str]:
    out = ["## Paper Table 5: the rough terrain model on slopes and stairs\n",
           "The PPO-CPG policy trained on rough ground, run on slopes and stairs (paper section 4.4, Table 5), "
           "on those protocol tasks themselves (20 seeded episodes per level, protocol seeds; success rate with "
           "its 95% Wilson interval), beside the paper's row (reported by the paper, not run here) and, for "
           "comparison, the same levels in the full-run records of the open-loop CPG and of PPO-CPG with the "
           "weights trained on that terrain.\n"]
    if not rows:
        return out + ["No records yet.\n"]
    for terrain, paper in PAPER_TABLE_5.items():
        levels = list(paper)
        unit = next(t.unit for t in suite.all_tasks if t.terrain == terrain)  # also where a protocol lacks a level
        header = ["Controller"] + [f"{format_level(v)} {unit}" for v in levels] + ["Trust", "Record", "git commit"]
        table = [["paper Table 5 (reported, not run here)"] + [f"{100 * paper[v]:.0f}%" for v in levels] + ["", "", ""]]
        for r in sorted((r for r in rows if r.terrain(terrain)), key=lambda r: r.label):
            table.append([md_text(r.label)] + [md_success_cell(r.level(terrain, v), True) for v in levels]
                         + [fmt_trust(r), md_text(r.source), md_text(str(r.details["git_commit"])[:12])])
        for r in context:  # the same tasks inside full-run records (their own terrain's weights)
            table.append([md_text(f"{r.label} (full-run record)")]
                         + [md_success_cell(r.level(terrain, v), True) for v in levels]
                         + [fmt_trust(r), md_text(r.source), md_text(str(r.details["git_commit"])[:12])])
        out += [f"### {terrain}\n", md_table(header, table) + "\n"]
    out.append("Commands:\n")
    for r in sorted(rows, key=lambda r: r.source):
        out.append(f"- {md_text(r.source, block=True)}: {md_code(r.details['command'])}")
    out.append("")
    return out


def _course_description(terrain: str) -> list[str]:
    if terrain != "mixed":
        return []
    from hexbench.world.terrain import MIXED_COURSE_LEVELS

    return ["Rough ground, then a slope, then four stairs in one episode; goal 6.3 m ahead "
            "(docs/protocol.md). Levels: " + "; ".join(
                f"{k}: rough {r:g} cm, slope {sl:g} deg, stairs {st:g} cm"
                for k, (r, sl, st) in MIXED_COURSE_LEVELS.items()) + ".\n"]


def _course_table(rows: list[Row], terrain: str, levels: list[float]) -> str:
    header = ["Controller"] + [f"level {format_level(v)}" for v in levels] + [
        "Mean speed [m/s]", "Episodes", "Trust", "Record", "Controller file", "git commit"]
    table = [[md_text(r.label)] + [md_success_cell(r.level(terrain, v), True) for v in levels] + [
        fmt_num(r.terrain(terrain)["mean_forward_speed_m_per_s"], 3), str(r.details["episodes"]), fmt_trust(r),
        md_text(r.source),
        md_text(r.details["controller_file"]), md_text(str(r.details["git_commit"])[:12])] for r in rows]
    return md_table(header, table)


def render_courses_readme(rows: list[Row], suite: Suite, table5_rows: list[Row] | None = None,
                          full_run_rows: tuple[Row, ...] = ()) -> str:
    out = [f"# hexbench extra courses: protocol {suite.protocol}\n",
           "Generated by `hexbench leaderboard build` from the result records in this folder (records of "
           "`hexbench run FILE --terrain mixed`); do not edit by hand. These courses are outside the full "
           "run and are not ranked with it. Success rate per level with the 95% Wilson interval; 20 seeded "
           "episodes per level.\n"]
    for terrain in suite.extra_terrains:
        course_rows = sorted((r for r in rows if r.terrain(terrain)), key=lambda r: r.label)
        out.append(f"## {terrain}\n")
        out += _course_description(terrain)
        if not course_rows:
            out.append("No records yet.\n")
            continue
        out.append(_course_table(course_rows, terrain, suite.levels(terrain)) + "\n")
        out.append("Commands:\n")
        for r in course_rows:
            out.append(f"- {md_text(r.label, block=True)}: {md_code(r.details['command'])}")
        out.append("")
    if table5_rows is not None:
        out += _table5_section(table5_rows, suite, [r for label in TABLE5_CONTEXT for r in full_run_rows
                                                    if r.label == label])
    return "\n".join(out)
