"""Reading an episode's MCAP file back: integrity check, metadata, messages, a text summary.

Episode files travel (the rollout dataset), so every read goes through `open_episode_file`: a
plain file of at most MAX_EPISODE_FILE_BYTES, read whole, whose compressed chunks each declare
at most MAX_CHUNK_UNCOMPRESSED_BYTES before any is decompressed (a 100 kB file can hold a zstd
chunk of gigabytes of zeros, which the MCAP reader would otherwise allocate and then walk as
millions of empty records).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.artifacts.files import read_bytes_bounded
from hexbench.errors import HexbenchError, InputError
from hexbench.world.robot import LEG_NAMES

# A recorded episode is about 0.7 kB per control step uncompressed (1.2 MB for 1,721 steps, 0.19 MB
# on disk): these bounds leave some 20 times the longest protocol episode (4,000 steps).
MAX_EPISODE_FILE_BYTES = 64 << 20
MAX_CHUNK_UNCOMPRESSED_BYTES = 64 << 20


class EpisodeFileError(HexbenchError):
    """An episode file is missing, unreadable or fails its CRC checks (one-line message)."""


def open_episode_file(path: str | Path) -> io.BytesIO:
    """The bytes of an episode file, for the MCAP reader, once the file is a plain file within
    MAX_EPISODE_FILE_BYTES and no chunk declares more than MAX_CHUNK_UNCOMPRESSED_BYTES;
    EpisodeFileError (one line) otherwise."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    try:
        data = read_bytes_bounded(path, MAX_EPISODE_FILE_BYTES, "episode file")
    except InputError as e:
        raise EpisodeFileError(str(e)) from None
    try:
        for record in StreamReader(io.BytesIO(data), emit_chunks=True).records:
            if isinstance(record, Chunk) and record.uncompressed_size > MAX_CHUNK_UNCOMPRESSED_BYTES:
                raise EpisodeFileError(f"{path}: a chunk declares {record.uncompressed_size:,} bytes uncompressed; "
                                       f"an episode file's chunks hold at most {MAX_CHUNK_UNCOMPRESSED_BYTES:,}")
    except EpisodeFileError:
        raise
    except Exception as e:  # noqa: BLE001 - any decoder failure means the file is unusable
        raise EpisodeFileError(f"{path}: corrupt MCAP file ({type(e).__name__}: {e})") from None
    return io.BytesIO(data)


@dataclass(frozen=True)
class EpisodeLog:
    path: Path
    episode: dict[str, str]  # metadata record "episode"
    outcome: dict  # metadata record "outcome" (values decoded from JSON)
    recording: dict[str, str]
    message_counts: dict[str, int]
    attachments: tuple[str, ...]


def _open_existing(path: Path) -> io.BytesIO:
    if not path.is_file():
        raise EpisodeFileError(f"{path}: no such episode file")
    return open_episode_file(path)


def check_integrity(path: str | Path) -> None:
    """Read every record with CRC validation (chunks, data section, summary); EpisodeFileError if bad."""
    _check_records(Path(path), _open_existing(Path(path)))


def _check_records(path: Path, f: io.BytesIO) -> None:
    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader

    try:
        for _ in StreamReader(f, validate_crcs=True).records:
            pass
    except (McapError, ValueError, EOFError, OSError) as e:
        raise EpisodeFileError(f"{path}: corrupt MCAP file ({type(e).__name__}: {e})") from None
    except Exception as e:  # noqa: BLE001 - any decoder failure means the file is unusable
        raise EpisodeFileError(f"{path}: unreadable MCAP file ({type(e).__name__}: {e})") from None


def read_episode(path: str | Path, validate: bool = True) -> EpisodeLog:
    from mcap.reader import make_reader

    path = Path(path)
    f = _open_existing(path)
    if validate:  # on the same bytes: the file is read (and its chunks' sizes checked) once
        _check_records(path, f)
        f.seek(0)
    with f:
        reader = make_reader(f, validate_crcs=True)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        summary = reader.get_summary()
        attachments = tuple(a.name for a in reader.iter_attachments())
    if "episode" not in meta:
        raise EpisodeFileError(f"{path}: not a hexbench episode (no 'episode' metadata record)")
    counts = {}
    if summary is not None and summary.statistics is not None:
        for cid, n in summary.statistics.channel_message_counts.items():
            counts[summary.channels[cid].topic] = n
    return EpisodeLog(path, meta["episode"], {k: json.loads(v) for k, v in meta.get("outcome", {}).items()},
                      meta.get("recording", {}), counts, attachments)


def iter_topic(path: str | Path, topic: str):
    """(log_time_ns, data bytes) of one topic in log-time order."""
    from mcap.reader import make_reader

    with open_episode_file(path) as f:
        for _, _, msg in make_reader(f, validate_crcs=True).iter_messages(topics=[topic], log_time_order=True):
            yield msg.log_time, msg.data


def metrics(path: str | Path) -> list[dict]:
    """The /metrics messages of an episode, decoded."""
    return [json.loads(data) for _, data in iter_topic(path, "/metrics")]


def all_messages(path: str | Path) -> dict[str, list[tuple[int, bytes]]]:
    from mcap.reader import make_reader

    out: dict[str, list[tuple[int, bytes]]] = {}
    with open_episode_file(path) as f:
        for _, channel, msg in make_reader(f, validate_crcs=True).iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append((msg.log_time, msg.data))
    return out


def summary_text(path: str | Path) -> str:
    """A human-readable summary of one episode file (what `hexbench replay --summary` prints)."""
    log = read_episode(path)
    rows = metrics(path)
    e, o = log.episode, log.outcome
    lines = [f"episode {e.get('episode_id', '?')}: {e.get('terrain')} level {e.get('level')} {e.get('unit', '')}, "
             f"seed {e.get('seed')}, protocol {e.get('protocol')}",
             f"controller {e.get('controller_file')} (sha256 {e.get('controller_sha256', '?')[:12]}), "
             f"action mode {e.get('action_mode')}, hexbench {e.get('hexbench_version')}"]
    if o:
        lines.append(f"outcome: {o.get('end_reason')} after {o.get('steps')} steps ({o.get('sim_time_s', 0):.2f} s), "
                     f"progress {o.get('progress_m', 0):.3f} m, max |y| {o.get('max_abs_y_m') or 0:.3f} m")
    if rows:
        contacts = np.array([r["foot_contacts"] for r in rows], dtype=float)
        last = rows[-1]
        if "return" in last:  # the return covers every step, also those /metrics does not log
            lines.append(f"reward: total {last['return']:.2f}, mean {last['return'] / last['step']:.3f} per step")
        else:
            reward = np.array([r["reward"] for r in rows])
            lines.append(f"reward: total {reward.sum():.2f}, mean {reward.mean():.3f} per step")
        lines.append("foot contact (fraction of logged steps): "
                     + ", ".join(f"{leg} {v:.2f}" for leg, v in zip(LEG_NAMES, contacts.mean(axis=0))))
    lines.append("channels: " + ", ".join(f"{t} {n}" for t, n in sorted(log.message_counts.items())))
    lines.append(f"attachments: {', '.join(log.attachments) or 'none'}")
    return "\n".join(lines)
