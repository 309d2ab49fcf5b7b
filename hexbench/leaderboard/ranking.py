"""Ranking of the measured entries, the per-controller statistics the outputs show, and the `Board`.

Ranking rule (measured entries only), per terrain: higher hardest level passed (success >= 80%,
None ranks below every level) first, then higher AUC (area under the success-vs-level curve over
the paper levels); entries equal on both share a rank. Overall: lower mean of the per-terrain
ranks first, then higher mean AUC, then label (alphabetical) as a stable tie-break. Reported
series are kept beside the ranking, never in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from hexbench.leaderboard.budget import Training, training_of
from hexbench.leaderboard.formatting import REPORTED_NOTE
from hexbench.leaderboard.records import LoadResult, Row
from hexbench.suite.tasks import DEFAULT_PROTOCOL, Suite, load_suite

RANKING_RULE = (
    "Per terrain, a controller ranks above another if it passes a harder level (success rate >= 80%; "
    "passing no level ranks last), and on equal hardest level if its AUC (area under the success-vs-level "
    "curve over the paper's Table 4 levels, 1.0 = every level at 100%) is higher; equal on both means an "
    "equal rank. The overall rank orders controllers by the mean of their three terrain ranks, then by "
    "mean AUC. Only measured entries are ranked; the paper's numbers are a reference, "
    f"{REPORTED_NOTE}."
)


@dataclass(frozen=True)
class Board:
    """Everything one build shows: measured rows ranked, reported rows kept apart."""

    protocol: str
    suite: Suite
    measured: tuple[Row, ...]  # in overall rank order
    reported: tuple[Row, ...]  # in record/series order
    terrain_ranks: dict  # terrain -> {label: rank}
    overall_ranks: dict  # label -> rank
    reported_notes: tuple[tuple[str, str], ...] = ()  # (citation, note) per reported record
    training: dict = field(default_factory=dict)  # label -> Training of each measured row


def _terrain_key(summary: dict | None) -> tuple[float, float]:
    if summary is None:
        return (-math.inf, -math.inf)
    hardest = summary["hardest_level_passed"]
    auc = summary["auc"]
    # AUCs are compared at 1e-9 so float round-off can never split a tie
    return (-math.inf if hardest is None else hardest, -math.inf if auc is None else round(auc, 9))


def rank_terrain(rows: list[Row], terrain: str) -> dict[str, int]:
    """Competition ranks (1, 1, 3, ...) by hardest level passed, then AUC (module docstring)."""
    keyed = sorted(((_terrain_key(r.terrain(terrain)), r.label) for r in rows), key=lambda kl: (
        tuple(-v for v in kl[0]), kl[1]))
    ranks, previous, rank = {}, None, 0
    for position, (k, label) in enumerate(keyed, start=1):
        if k != previous:
            rank, previous = position, k
        ranks[label] = rank
    return ranks


def rank_overall(rows: list[Row], terrains: tuple[str, ...]) -> tuple[list[Row], dict[str, dict[str, int]], dict[str, int]]:
    """Rows in overall order, per-terrain ranks and overall ranks (module docstring)."""
    terrain_ranks = {t: rank_terrain(rows, t) for t in terrains}

    def mean_rank(r: Row) -> float:
        return sum(terrain_ranks[t][r.label] for t in terrains) / len(terrains) if terrains else 0.0

    def mean_auc(r: Row) -> float:
        aucs = [(r.terrain(t) or {}).get("auc") for t in terrains]
        return round(sum(a if a is not None else 0.0 for a in aucs) / len(aucs), 9) if aucs else 0.0

    ordered = sorted(rows, key=lambda r: (mean_rank(r), -mean_auc(r), r.label))
    overall, previous, rank = {}, None, 0
    for position, r in enumerate(ordered, start=1):
        k = (mean_rank(r), mean_auc(r))
        if k != previous:
            rank, previous = position, k
        overall[r.label] = rank
    return ordered, terrain_ranks, overall


def make_board(load: LoadResult, protocol: str = DEFAULT_PROTOCOL, root: Path | None = None) -> Board:
    """Rank the loaded rows; `root` is where records' checkpoint paths resolve (None: budgets unknown)."""
    suite = load_suite(protocol)
    measured = [r for r in load.rows if r.kind == "measured"]
    reported = [r for r in load.rows if r.kind == "reported"]
    ordered, terrain_ranks, overall = rank_overall(measured, suite.terrains)
    notes = tuple(dict.fromkeys((r.details["citation"], r.details["note"]) for r in reported))
    training = {r.label: training_of(r, root) if root is not None else Training(known=False) for r in measured}
    return Board(protocol, suite, tuple(ordered), tuple(reported), terrain_ranks, overall, notes, training)


def _mean(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return sum(vals) / len(vals) if vals else None


def overall_metrics(row: Row) -> dict:
    """Means over terrains of the per-terrain means (speed, roll/pitch RMS)."""
    return {
        "mean_forward_speed_m_per_s": _mean([t["mean_forward_speed_m_per_s"] for t in row.terrains]),
        "mean_roll_rms_deg": _mean([t.get("mean_roll_rms_deg") for t in row.terrains]),
        "mean_pitch_rms_deg": _mean([t.get("mean_pitch_rms_deg") for t in row.terrains]),
        "episodes": sum(t["episodes"] for t in row.terrains),
    }
