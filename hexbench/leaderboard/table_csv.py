"""leaderboard.csv: every number of the build in long format, one row per controller x terrain x level.

Free-text cells from records (labels, file names) are defused for spreadsheets: one that would start
a formula gets a leading apostrophe. Numbers are written as numbers.
"""

from __future__ import annotations

import csv
import io

from hexbench.leaderboard.budget import Training
from hexbench.leaderboard.formatting import fmt_trust
from hexbench.leaderboard.ranking import Board

CSV_COLUMNS = ("kind", "setting", "controller", "record", "overall_rank", "terrain_rank", "terrain", "unit", "level",
               "headroom", "episodes", "successes", "success_rate", "ci95_low", "ci95_high",
               "level_mean_forward_speed_m_per_s", "terrain_hardest_level_passed", "terrain_auc",
               "terrain_headroom_auc", "terrain_mean_forward_speed_m_per_s", "terrain_mean_roll_rms_deg",
               "terrain_mean_pitch_rms_deg", "training_env_step_budget", "checkpoint_env_steps", "trust")

# A spreadsheet evaluates a cell starting with one of these as a formula (OWASP "CSV injection").
CSV_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _csv_value(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(round(v, 6))
    return str(v)


def _csv_text(v) -> str:
    """A free-text cell from a record (label, file name): a leading apostrophe where the text would
    start a spreadsheet formula, so it shows as text. Never for numbers (a negative number stays one)."""
    s = _csv_value(v)
    return "'" + s if s.startswith(CSV_FORMULA_START) else s


def _csv_training(training: Training | None) -> tuple[str | None, str | None]:
    """Budget and checkpoint env steps as CSV cells: distinct values joined by ';', empty if unknown."""
    if training is None or not training.known:
        return None, None
    return ";".join(map(str, training.budgets)), ";".join(map(str, training.env_steps))


def render_csv(board: Board) -> str:
    """Long format: one row per controller x terrain x level, terrain summary columns repeated."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for r in (*board.measured, *board.reported):
        for lv in r.levels:
            t = r.terrain(lv["terrain"])
            measured = r.kind == "measured"
            writer.writerow([r.kind, r.setting, _csv_text(r.label), _csv_text(r.source)] + [_csv_value(v) for v in (
                board.overall_ranks[r.label] if measured else None,
                board.terrain_ranks[lv["terrain"]][r.label] if measured else None,
                lv["terrain"], lv["unit"], lv["level"], lv["headroom"], lv["episodes"], lv["successes"],
                lv["success_rate"], lv["ci95_low"], lv["ci95_high"], lv["mean_forward_speed_m_per_s"],
                t["hardest_level_passed"], t["auc"], t["headroom_auc"], t["mean_forward_speed_m_per_s"],
                t.get("mean_roll_rms_deg"), t.get("mean_pitch_rms_deg"),
                *_csv_training(board.training.get(r.label) if measured else None),
                fmt_trust(r) if measured else "reported")])
    return buf.getvalue()
