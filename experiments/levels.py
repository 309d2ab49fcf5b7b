"""Diagnostic tasks at levels between suite levels, e.g. slopes 19.5 deg: the helper compare_checkpoints.py
and crest_residual.py share. Run them as `python experiments/NAME.py`, which puts experiments/ on the
import path.
"""

from __future__ import annotations

from dataclasses import replace

from hexbench.suite.tasks import Suite, TaskSpec


def task_between(suite: Suite, terrain: str, level: float) -> TaskSpec:
    """The suite level's own task, else the next suite level up with this level: its rules (step limit,
    corridor, stall window), the terrain built at `level`, seeds derived from `level`. Never scored;
    for probing thresholds between suite levels. ValueError for an unknown terrain or a level above
    the terrain's top."""
    try:
        return suite.task(terrain, level)
    except ValueError as e:
        above = [t for t in suite.all_tasks if t.terrain == terrain and t.level > float(level)]
        if not above:
            raise ValueError(f"{e} (or any level below the top)") from None
        return replace(min(above, key=lambda t: t.level), level=float(level))
