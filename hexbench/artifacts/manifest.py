"""The checkpoint manifest (`manifest.json` beside shipped or published weights): its one owner.

    {"format": 1, "note": "...", "checkpoints": {"<method>-<terrain>": {"file": "<name>.zip",
      "sha256": "...", "env_step_budget": N, "env_steps": N, "command": "...", "seed": S, ...}}}

Every entry names its weights file (relative to the manifest's folder) and that file's sha256;
weights are hashed against their entry before anything opens them. `hexbench checkpoints publish`
writes entries (`write_entry`), the trained-policy controllers and warm starts read them strictly
(`read_manifest`, `entry_for`, `verify_checkpoint`), and the leaderboard looks entries up by the
sha256 a record names (`entries_by_sha256`, lenient: a missing or broken manifest claims nothing).
"""

from __future__ import annotations

from pathlib import Path

from hexbench.artifacts.files import read_json_bounded, sha256_file, write_json_atomic
from hexbench.errors import HexbenchError, InputError

MANIFEST_NAME = "manifest.json"
FORMAT = 1
MAX_MANIFEST_BYTES = 4 << 20  # a manifest of a few hundred entries is tens of kB; larger is refused unread
NOTE = ("shipped baseline weights: policy state_dict only (SB3 zip without pickled data); "
        "written by `hexbench checkpoints publish`")


class CheckpointError(HexbenchError):
    """A checkpoint or its manifest is missing, corrupt, tampered with or unusable; one line."""


def manifest_path(checkpoints_dir: Path) -> Path:
    return Path(checkpoints_dir) / MANIFEST_NAME


def read_manifest(checkpoints_dir: Path) -> dict:
    """The manifest in `checkpoints_dir`; CheckpointError if it is missing or malformed."""
    path = manifest_path(checkpoints_dir)
    if not path.is_file():
        raise CheckpointError(f"{path}: no checkpoint manifest")
    try:
        data = read_json_bounded(path, MAX_MANIFEST_BYTES, "checkpoint manifest")
    except InputError as e:
        raise CheckpointError(str(e)) from None
    if not isinstance(data, dict) or not isinstance(data.get("checkpoints"), dict):
        raise CheckpointError(f"{path}: has no 'checkpoints' table")
    return data


def entry_for(checkpoints_dir: Path, key: str) -> tuple[Path, dict]:
    """(weights path, entry) for `key` (e.g. "ppo_cpg-rough"); CheckpointError naming the keys there are."""
    manifest = read_manifest(checkpoints_dir)
    entry = manifest["checkpoints"].get(key)
    if entry is None:
        have = ", ".join(sorted(manifest["checkpoints"])) or "none"
        raise CheckpointError(f"{manifest_path(checkpoints_dir)}: no checkpoint {key!r}; shipped: {have}")
    return Path(checkpoints_dir) / entry["file"], entry


def verify_checkpoint(path: Path, expected_sha256: str) -> None:
    """CheckpointError unless `path` exists and hashes to `expected_sha256`."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint file missing")
    actual = sha256_file(path)
    if actual != expected_sha256:
        raise CheckpointError(f"{path}: sha256 {actual[:12]}... does not match the manifest's "
                              f"{expected_sha256[:12]}... (corrupt or tampered); refusing to load it")


def entries_by_sha256(checkpoints_dir: Path) -> dict[str, dict]:
    """The manifest's entries keyed by their sha256; {} if it is missing or unreadable."""
    try:
        entries = read_manifest(checkpoints_dir)["checkpoints"]
    except CheckpointError:
        return {}
    return {e["sha256"]: e for e in entries.values() if isinstance(e, dict) and isinstance(e.get("sha256"), str)}


def write_entry(checkpoints_dir: Path, key: str, entry: dict) -> dict:
    """Add or replace `key` in the manifest of `checkpoints_dir` (created if absent), atomically."""
    path = manifest_path(checkpoints_dir)
    manifest = read_manifest(checkpoints_dir) if path.exists() else {"format": FORMAT, "note": NOTE, "checkpoints": {}}
    manifest["checkpoints"][key] = entry
    write_json_atomic(path, manifest)
    return entry
