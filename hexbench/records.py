"""What a record's episode rows hold, and the digest that binds them.

Each episode row of a record carries the outcome fields (hexbench.rollout.ROW_FIELDS) and the
name and sha256 of its action log; the record carries `episodes_digest`, the sha256 of the
canonical JSON of its rows in (terrain, level, index) order. Anyone who re-runs a controller can
compare episode by episode (the log hashes), and any edit of a row changes the digest.
"""

from __future__ import annotations

import hashlib
import json

from hexbench.rollout import ROW_FIELDS

LOG_FIELDS: tuple[str, ...] = ("action_log_path", "action_log_sha256")


def episode_record_rows(rows: list[dict]) -> list[dict]:
    """The rows as a record stores them: outcome fields and action-log fields, sorted."""
    keep = ROW_FIELDS + LOG_FIELDS
    return sorted(({k: r[k] for k in keep if k in r} for r in rows), key=lambda r: (r["terrain"], r["level"], r["index"]))


def episodes_digest(rows: list[dict]) -> str:
    canonical = json.dumps(episode_record_rows(rows), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(canonical.encode()).hexdigest()
