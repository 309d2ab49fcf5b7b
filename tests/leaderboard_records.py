"""Synthetic measured result records for the leaderboard tests (schema-valid, protocol seeds).

Not real results: every episode outcome is drawn from a made-up logistic success curve with a
seeded np.random.Generator, only to exercise validation, ranking and rendering.
"""

from __future__ import annotations

import copy
import json
import math
import shutil
from pathlib import Path

import numpy as np

from hexbench.artifacts.records import episodes_digest
from hexbench.suite.scoring import summarize_levels, summarize_terrains
from hexbench.suite.tasks import load_suite

END_REASONS_FAILED = ("fall", "lateral_deviation", "stalled", "step_limit")
PAPER_REFERENCE = Path(__file__).resolve().parent.parent / "leaderboard" / "paper_reference.json"


def synthetic_record(label: str, capability: dict[str, float], seed: int, *, protocol: str = "v1",
                     episodes: int | None = None, slope_width: float = 0.6, courses: bool = False,
                     terrains: tuple[str, ...] | None = None, levels: dict | None = None) -> dict:
    """A measured record whose success probability falls from 1 to 0 around `capability[terrain]`
    (of the full run, or with courses=True of the extra courses; `terrains` or `levels`: of those alone)."""
    suite = load_suite(protocol)
    rng = np.random.default_rng(seed)
    rows = []
    tasks = suite.extra_tasks if courses else suite.tasks
    if terrains is not None:
        tasks = tuple(t for t in tasks if t.terrain in terrains)
    if levels is not None:  # {terrain: levels}: those tasks alone
        tasks = tuple(t for t in tasks if t.level in levels.get(t.terrain, ()))
    for task in tasks:
        p = 1.0 / (1.0 + math.exp((task.level - capability[task.terrain]) / slope_width))
        for index, ep_seed in enumerate(task.seeds(episodes)):
            success = bool(rng.random() < p)
            speed = float(rng.uniform(0.05, 0.15))
            rows.append({
                "terrain": task.terrain, "level": task.level, "index": index, "seed": ep_seed, "success": success,
                "end_reason": "success" if success else END_REASONS_FAILED[int(rng.integers(len(END_REASONS_FAILED)))],
                "steps": int(rng.integers(600, 4000)), "sim_time_s": float(rng.uniform(10, 66)),
                "progress_m": 2.5 if success else float(rng.uniform(0, 2.4)),
                "time_to_goal_s": 2.5 / speed if success else None, "mean_forward_speed_m_per_s": speed,
                "max_abs_y_m": float(rng.uniform(0, 0.5)), "roll_rms_deg": float(rng.uniform(1, 6)),
                "pitch_rms_deg": float(rng.uniform(1, 6)), "cost_of_transport": float(rng.uniform(1, 4)),
            })
    units = {t.terrain: t.unit for t in tasks}
    headroom = {(t.terrain, t.level): t.headroom for t in tasks}
    levels = summarize_levels(rows, units, headroom)
    return {
        "schema_version": 1, "protocol": protocol, "label": label, "kind": "measured",
        "controller": {"file": f"baselines/{label}.py", "sha256": f"{seed:064x}"[-64:], "action_mode": "cpg_residual",
                       "checkpoints": []},
        "provenance": {"hexbench_version": "0.1.0", "git_commit": "0123456789abcdef0123456789abcdef01234567",
                       "command": f"hexbench run baselines/{label}.py", "machine": {"hostname": "test"},
                       "started_at": "2026-01-01T00:00:00+00:00", "wall_time_s": 123.0, "workers": 2},
        "levels": levels, "terrains": summarize_terrains(levels), "episodes": rows,
    }


def demo_records() -> list[dict]:
    """Three synthetic controllers of clearly different ability."""
    return [
        synthetic_record("strong", {"rough": 12.5, "slopes": 17.0, "stairs": 8.2}, seed=1),
        synthetic_record("middling", {"rough": 9.5, "slopes": 11.5, "stairs": 6.0}, seed=2),
        synthetic_record("weak", {"rough": 7.0, "slopes": 9.0, "stairs": 4.5}, seed=3),
    ]


def write_board(folder: Path, records: list[dict]) -> Path:
    """`folder` made a leaderboard folder holding `records` (as <label>.json) and the paper reference."""
    folder.mkdir(exist_ok=True)
    for r in records:
        (folder / f"{r['label']}.json").write_text(json.dumps(r))
    shutil.copy(PAPER_REFERENCE, folder / "paper_reference.json")
    return folder


def mutated(record: dict, change) -> dict:
    out = copy.deepcopy(record)
    change(out)
    return out


def resummarize(record: dict) -> None:
    """Recompute a record's level and terrain summaries and its episodes digest from its rows, in
    place: what a forger who edits rows does to keep the record self-consistent."""
    units = {lv["terrain"]: lv["unit"] for lv in record["levels"]}
    headroom = {(lv["terrain"], lv["level"]): lv["headroom"] for lv in record["levels"]}
    record["levels"] = summarize_levels(record["episodes"], units, headroom)
    record["terrains"] = summarize_terrains(record["levels"])
    record["episodes_digest"] = episodes_digest(record["episodes"])
