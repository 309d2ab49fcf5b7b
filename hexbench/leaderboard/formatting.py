"""How numbers, levels, trust tiers and names read in every output (README, index.html, CSV, plots)."""

from __future__ import annotations

import re

from hexbench.leaderboard.records import TIER_SELF_REPORTED, Row, episodes_rerun
from hexbench.suite.tasks import format_level

REPORTED_NOTE = "reported by the paper, not run here"
TERRAIN_TITLES = {"rough": "Rough terrain", "slopes": "Slopes", "stairs": "Stairs"}
TERRAIN_AXES = {"rough": "height difference", "slopes": "slope angle", "stairs": "step height"}

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")  # newlines would end a table row or paragraph


def one_line(text) -> str:
    """`text` on one line: control characters (newlines included) become spaces (Markdown cells,
    plot legends)."""
    return _CONTROL.sub(" ", str(text))


def pct(rate: float | None) -> str:
    return "–" if rate is None else f"{100 * rate:.0f}%"


def fmt_level(level: float | None, unit: str) -> str:
    return "none" if level is None else f"{format_level(level)} {unit}"


def fmt_num(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def reported_name(row: Row) -> str:
    return f"{row.label}: reported, not run here"


def fmt_trust(row: Row) -> str:
    """The row's trust tier, with how much of it was replayed where not all, and "+ re-run" where
    admission also played the episodes again with the named controller (`leaderboard add --rerun`)."""
    tier = row.details.get("tier", TIER_SELF_REPORTED)
    if tier == TIER_SELF_REPORTED:
        return tier
    admission = row.details.get("admission") or {}
    replayed, total = admission.get("episodes_replayed"), admission.get("episodes_total")
    text = f"{tier} ({replayed} of {total} replayed)" if replayed is not None and total and replayed < total else tier
    rerun = episodes_rerun(admission)
    if rerun:
        text += " + re-run" + (f" ({rerun} of {total})" if total and rerun < total else "")
    return text
