"""The action log: the exact action of every control step of one episode (the only owner of the format).

The physics is deterministic, so (task, episode seed, actions) replays an episode without its
controller: `hexbench verify` and leaderboard admission do exactly that. The evaluator applies
every action as float32 (the action space's dtype), so the log holds what the simulator saw, bit
for bit.

File layout (`<episode id>.actions`, deterministic bytes):

    b"HXACT1\\n"                      magic and format version
    header JSON (sorted keys) b"\\n"  protocol, terrain, level, index, seed, action_mode, steps, dim
    zlib(level 9) of the actions     float32 little-endian, byte planes shuffled (all first bytes,
                                     then all second bytes, ...), which compresses policy outputs
                                     about 15% better than the plain array

Reading checks everything (magic, header fields, the decompressed size against steps x dim,
with a bound before decompressing), so a corrupt or hostile file is one `ActionLogError`.
"""

from __future__ import annotations

import hashlib
import json
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.artifacts.files import read_bytes_bounded, write_bytes_atomic
from hexbench.errors import HexbenchError, InputError

MAGIC = b"HXACT1\n"
SUFFIX = ".actions"
MAX_HEADER_BYTES = 4096
MAX_STEPS = 100_000  # far above any protocol's step limit; bounds what a reader decompresses
MAX_DIM = 64
# The largest file a log of MAX_STEPS x MAX_DIM float32 actions can be (zlib adds at most some 0.1% to
# what does not compress, plus a few bytes) [bytes]: a reader refuses anything larger before reading it.
MAX_FILE_BYTES = len(MAGIC) + MAX_HEADER_BYTES + 1 + MAX_STEPS * MAX_DIM * 4 * 1001 // 1000 + 64
HEADER_FIELDS = ("protocol", "terrain", "level", "index", "seed", "action_mode", "steps", "dim")


class ActionLogError(HexbenchError):
    """An action log is missing, corrupt or does not belong to the episode it is read for."""


@dataclass(frozen=True)
class ActionLog:
    protocol: str
    terrain: str
    level: float
    index: int
    seed: int
    action_mode: str
    actions: np.ndarray  # (steps, dim) float32

    @property
    def steps(self) -> int:
        return int(self.actions.shape[0])

    @property
    def dim(self) -> int:
        return int(self.actions.shape[1])

    def header(self) -> dict:
        return {"protocol": self.protocol, "terrain": self.terrain, "level": float(self.level), "index": self.index,
                "seed": self.seed, "action_mode": self.action_mode, "steps": self.steps, "dim": self.dim}


def encode(log: ActionLog) -> bytes:
    actions = np.ascontiguousarray(log.actions, dtype="<f4")
    planes = actions.view(np.uint8).reshape(-1, 4).T.tobytes()
    header = json.dumps(log.header(), sort_keys=True, separators=(",", ":")).encode()
    return MAGIC + header + b"\n" + zlib.compress(planes, 9)


def decode(data: bytes, where: str = "action log") -> ActionLog:
    if not data.startswith(MAGIC):
        raise ActionLogError(f"{where}: not a hexbench action log (bad magic)")
    end = data.find(b"\n", len(MAGIC), len(MAGIC) + MAX_HEADER_BYTES)
    if end < 0:
        raise ActionLogError(f"{where}: action log header is missing or too long")
    try:
        header = json.loads(data[len(MAGIC):end])
        values = {k: header[k] for k in HEADER_FIELDS}
        steps, dim = int(values["steps"]), int(values["dim"])
    except (ValueError, KeyError, TypeError) as e:
        raise ActionLogError(f"{where}: action log header is corrupt ({type(e).__name__}: {e})") from None
    if not (0 <= steps <= MAX_STEPS and 1 <= dim <= MAX_DIM):
        raise ActionLogError(f"{where}: action log header gives {steps} steps x {dim} actions, outside 0-{MAX_STEPS} x 1-{MAX_DIM}")
    size = steps * dim * 4
    try:
        inflater = zlib.decompressobj()
        planes = inflater.decompress(data[end + 1:], size + 1)
        if len(planes) != size or inflater.unconsumed_tail or not inflater.eof:
            raise ActionLogError(f"{where}: action log body does not hold {steps} x {dim} float32 actions")
    except zlib.error as e:
        raise ActionLogError(f"{where}: action log body is corrupt ({e})") from None
    actions = np.frombuffer(planes, np.uint8).reshape(4, -1).T.copy().view("<f4").reshape(steps, dim)
    return ActionLog(protocol=str(values["protocol"]), terrain=str(values["terrain"]), level=float(values["level"]),
                     index=int(values["index"]), seed=int(values["seed"]), action_mode=str(values["action_mode"]),
                     actions=actions.astype(np.float32))


def write(path: Path, log: ActionLog) -> str:
    """Write the log atomically; return the sha256 of its bytes (what episode rows carry)."""
    data = encode(log)
    write_bytes_atomic(path, data)
    return hashlib.sha256(data).hexdigest()


def read(path: Path, expected_sha256: str | None = None) -> ActionLog:
    """Read and check a log; with `expected_sha256`, the file must hash to it."""
    try:
        data = read_bytes_bounded(path, MAX_FILE_BYTES, "action log")
    except InputError as e:
        raise ActionLogError(str(e)) from None
    if expected_sha256 is not None and hashlib.sha256(data).hexdigest() != expected_sha256:
        raise ActionLogError(f"{path}: action log sha256 differs from the one in its episode row")
    return decode(data, str(path))
