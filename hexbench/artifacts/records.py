"""What a record's episode rows hold, and the digest that binds them.

Each episode row of a record carries the outcome fields (`ROW_FIELDS`, computed by hexbench.suite.rollout.play) and the
name and sha256 of its action log; the record carries `episodes_digest`, the sha256 of the
canonical JSON of its rows in (terrain, level, index) order. Anyone who re-runs a controller can
compare episode by episode (the log hashes), and any edit of a row changes the digest.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from hexbench.artifacts.files import read_json_bounded

RESULT_SCHEMA = Path(__file__).parent / "schemas" / "result.schema.json"  # the schema of result.json
# The most a result record may weigh [bytes]: a full protocol v1 record is about 0.6 MB; a larger
# file is refused before it is read (records arrive from anyone, through `hexbench leaderboard add`).
MAX_RECORD_BYTES = 64 << 20
# The outcome of one episode, as hexbench.suite.rollout.play computes it
ROW_FIELDS: tuple[str, ...] = ("terrain", "level", "index", "seed", "success", "end_reason", "steps", "sim_time_s",
                               "progress_m", "time_to_goal_s", "mean_forward_speed_m_per_s", "max_abs_y_m",
                               "roll_rms_deg", "pitch_rms_deg", "cost_of_transport")
LOG_FIELDS: tuple[str, ...] = ("action_log_path", "action_log_sha256")


def episode_record_rows(rows: list[dict]) -> list[dict]:
    """The rows as a record stores them: outcome fields and action-log fields, sorted."""
    keep = ROW_FIELDS + LOG_FIELDS
    return sorted(({k: r[k] for k in keep if k in r} for r in rows), key=lambda r: (r["terrain"], r["level"], r["index"]))


def episodes_digest(rows: list[dict]) -> str:
    canonical = json.dumps(episode_record_rows(rows), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(canonical.encode()).hexdigest()


def read_record_json(path: str | Path):
    """The parsed JSON of a result record file, read only if it is a plain file of at most
    MAX_RECORD_BYTES (InputError, one line, otherwise or if it is not JSON)."""
    return read_json_bounded(path, MAX_RECORD_BYTES, "result record")


def validate_record(record: dict) -> None:
    import jsonschema

    jsonschema.validate(record, json.loads(RESULT_SCHEMA.read_text()))
