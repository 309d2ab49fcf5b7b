"""Scores: per-episode outcomes -> per-level success rates (Wilson 95%) -> per-terrain summary.

Definitions (protocol v1, also in docs/protocol.md):
  success rate        successes / episodes at one level, with the 95% Wilson score interval;
  hardest level passed the highest level whose success rate is >= 80% (None if none is);
  AUC                 area under the success-vs-level curve over the paper (Table 4) levels,
                      trapezoidal in level units and divided by the level span: 1.0 means every
                      paper level at 100%. `headroom_auc` is the same over the headroom levels.
Per-level means of the motion metrics (speed, time to goal, roll/pitch RMS, cost of transport)
are taken over successful episodes where the metric only exists for them (time to goal), and
over all episodes otherwise.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Iterable

import numpy as np

PASS_THRESHOLD = 0.8
Z_95 = 1.959963984540054


def wilson_interval(successes: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """95% Wilson score interval for a binomial proportion."""
    if n <= 0:
        return (0.0, 1.0)
    phat = successes / n
    denom = 1.0 + z * z / n
    centre = (phat + z * z / (2 * n)) / denom
    half = z * math.sqrt(phat * (1 - phat) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def _mean(values: list[float]) -> float | None:
    vals = [v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return float(np.mean(vals)) if vals else None


def summarize_levels(episodes: Iterable[dict], units: dict[str, str], headroom: dict[tuple[str, float], bool]) -> list[dict]:
    """Group episode rows by (terrain, level) into level records, sorted by terrain then level."""
    groups: dict[tuple[str, float], list[dict]] = defaultdict(list)
    for e in episodes:
        groups[(e["terrain"], float(e["level"]))].append(e)
    out = []
    for (terrain, level), rows in sorted(groups.items()):
        rows = sorted(rows, key=lambda r: r["index"])
        n, k = len(rows), sum(1 for r in rows if r["success"])
        lo, hi = wilson_interval(k, n)
        out.append({
            "terrain": terrain, "level": level, "unit": units[terrain], "headroom": headroom[(terrain, level)],
            "episodes": n, "successes": k, "success_rate": k / n if n else 0.0,
            "ci95_low": lo, "ci95_high": hi, "seeds": [int(r["seed"]) for r in rows],
            "mean_forward_speed_m_per_s": _mean([r["mean_forward_speed_m_per_s"] for r in rows]),
            "mean_time_to_goal_s": _mean([r["time_to_goal_s"] for r in rows if r["success"]]),
            "mean_max_abs_y_m": _mean([r["max_abs_y_m"] for r in rows]),
            "mean_roll_rms_deg": _mean([r["roll_rms_deg"] for r in rows]),
            "mean_pitch_rms_deg": _mean([r["pitch_rms_deg"] for r in rows]),
            "mean_cost_of_transport": _mean([r["cost_of_transport"] for r in rows]),
        })
    return out


def area_under_curve(levels: list[float], rates: list[float]) -> float | None:
    """Trapezoidal area under success rate vs level, divided by the level span (0..1)."""
    if not levels:
        return None
    if len(levels) == 1:
        return float(rates[0])
    order = np.argsort(levels)
    x = np.asarray(levels, dtype=float)[order]
    y = np.asarray(rates, dtype=float)[order]
    return float(np.sum((y[1:] + y[:-1]) * np.diff(x)) / 2.0 / (x[-1] - x[0]))


def summarize_terrains(levels: list[dict]) -> list[dict]:
    """Per-terrain summary from level records (see module docstring)."""
    by_terrain: dict[str, list[dict]] = defaultdict(list)
    for lv in levels:
        by_terrain[lv["terrain"]].append(lv)
    out = []
    for terrain, rows in sorted(by_terrain.items()):
        rows = sorted(rows, key=lambda r: r["level"])
        passed = [r["level"] for r in rows if r["success_rate"] >= PASS_THRESHOLD]
        paper = [r for r in rows if not r["headroom"]]
        extra = [r for r in rows if r["headroom"]]
        episodes = sum(r["episodes"] for r in rows)
        speeds = [r["mean_forward_speed_m_per_s"] for r in rows if r["mean_forward_speed_m_per_s"] is not None]
        out.append({
            "terrain": terrain, "unit": rows[0]["unit"],
            "hardest_level_passed": max(passed) if passed else None,
            "auc": area_under_curve([r["level"] for r in paper], [r["success_rate"] for r in paper]),
            "headroom_auc": area_under_curve([r["level"] for r in extra], [r["success_rate"] for r in extra]),
            "episodes": episodes,
            "successes": sum(r["successes"] for r in rows),
            "mean_forward_speed_m_per_s": float(np.mean(speeds)) if speeds else None,
            "mean_roll_rms_deg": _mean([r["mean_roll_rms_deg"] for r in rows]),
            "mean_pitch_rms_deg": _mean([r["mean_pitch_rms_deg"] for r in rows]),
        })
    return out
