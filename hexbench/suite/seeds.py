"""Seed sets: the public protocol seeds, hidden seed sets from a secret key, and controller seeds.

- Public: seed_i = first 4 bytes of sha256("hexbench/<protocol>/<terrain>/<level>/<i>")
  (hexbench.suite.tasks.episode_seed). Anyone can rebuild these episodes; a record names the set "public".
- Keyed (`hexbench run --seed-key FILE`): seed_i = first 4 bytes of HMAC-SHA256(key, the same
  string). Without the key nobody can rebuild the terrain or the noise of an episode, so a
  maintainer can score a submission on episodes nobody has seen. A record names the set by the
  key's fingerprint (first 16 hex digits of sha256(key)), never the key.
- Controller seed: what a controller's reset() receives: HMAC-SHA256(run secret, "reset/<seed>"),
  4 bytes. The run secret is random per run folder and never leaves the evaluator, so the seed a
  controller gets does not rebuild its episode's terrain or observation noise.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from dataclasses import dataclass
from pathlib import Path

from hexbench.artifacts.files import write_bytes_atomic
from hexbench.errors import HexbenchError

MIN_KEY_BYTES = 16
RUN_SECRET_FILE = "run_secret"


class SeedKeyError(HexbenchError):
    """A seed key file is missing, unreadable or too short."""


@dataclass(frozen=True)
class SeedSet:
    """How a run's episode seeds are made: public, or keyed by a secret (only its fingerprint is shown)."""

    key: bytes | None = None
    source: str | None = None  # the key file (kept out of the controller's sight), if read from one

    @property
    def kind(self) -> str:
        return "public" if self.key is None else "keyed"

    def fingerprint(self) -> str | None:
        return None if self.key is None else hashlib.sha256(self.key).hexdigest()[:16]

    def record(self) -> dict:
        return {"kind": "public"} if self.key is None else {"kind": "keyed", "key_fingerprint": self.fingerprint()}

    def seeds(self, task, episodes: int | None = None) -> list[int]:
        if self.key is None:
            return task.seeds(episodes)
        from hexbench.suite.tasks import format_level

        n = task.episodes if episodes is None else episodes
        return [keyed_seed(self.key, f"hexbench/{task.protocol}/{task.terrain}/{format_level(task.level)}/{i}")
                for i in range(n)]


def keyed_seed(key: bytes, message: str) -> int:
    return int.from_bytes(hmac.new(key, message.encode(), hashlib.sha256).digest()[:4], "big")


def read_seed_key(path: str | Path) -> SeedSet:
    try:
        key = Path(path).read_bytes().strip()
    except OSError as e:
        raise SeedKeyError(f"{path}: seed key cannot be read ({e.strerror or e})") from None
    if len(key) < MIN_KEY_BYTES:
        raise SeedKeyError(f"{path}: seed key is {len(key)} bytes; use at least {MIN_KEY_BYTES} random bytes "
                           f"(e.g. `head -c 32 /dev/urandom | base64 > key`)")
    return SeedSet(key, str(Path(path).resolve()))


def run_secret(journal_dir: Path) -> bytes:
    """The run folder's secret (made on first use, owner-only; kept for resume)."""
    path = journal_dir / RUN_SECRET_FILE
    if path.is_file():
        return bytes.fromhex(path.read_text().strip())
    secret = secrets.token_bytes(32)
    write_bytes_atomic(path, secret.hex().encode())
    path.chmod(0o600)
    return secret


def controller_seed(secret: bytes, episode_seed: int) -> int:
    return keyed_seed(secret, f"reset/{episode_seed}")
