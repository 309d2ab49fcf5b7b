"""Hashing and atomic writes: the one place files are hashed and written whole or not at all.

A write goes to a hidden temporary name beside the target and is renamed over it when complete, so
a reader never sees half a file. Any OS failure (read-only folder, a file where a folder should be,
a name too long, a full disk) removes the temporary file and becomes one `OutputError` line.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hexbench.errors import OutputError

_REASONS = {errno.EROFS: "read-only file system", errno.EACCES: "permission denied", errno.EPERM: "permission denied",
            errno.ENOTDIR: "a path component is a file, not a folder", errno.EISDIR: "is a folder",
            errno.ENAMETOOLONG: "file name too long", errno.ENOSPC: "no space left on device",
            errno.EDQUOT: "disk quota exceeded", errno.EEXIST: "exists and is not a folder"}


def os_reason(error: OSError) -> str:
    return _REASONS.get(error.errno, error.strerror or type(error).__name__)


def sha256_file(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def make_folder(path: Path) -> None:
    """mkdir -p, as one OutputError line on failure."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{path}: cannot create the folder ({os_reason(e)})") from None
    if not Path(path).is_dir():
        raise OutputError(f"{path}: exists and is not a folder")


def check_writable(folder: Path, named: Path | None = None) -> None:
    """OutputError unless a file can be made in `folder` (an empty probe, removed at once); the line
    names `named` (default: the folder), e.g. a folder still to be made under `folder`."""
    probe = Path(folder) / f".write-probe-{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise OutputError(f"{named or folder}: cannot be written ({os_reason(e)})") from None


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary name beside `path` for a writer that wants a file name (pandas, torch, SB3,
    matplotlib): renamed over `path` when the block ends without error, removed otherwise. The
    temporary name keeps the suffix, for writers that choose the format by it."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        _remove_quietly(tmp)
        raise OutputError(f"{path}: cannot be written ({os_reason(e)})") from None
    except BaseException:
        _remove_quietly(tmp)
        raise


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    write_bytes_atomic(path, text.encode())


def write_json_atomic(path: str | Path, data, indent: int = 2) -> None:
    """`data` as indented JSON with a final newline, written atomically."""
    write_text_atomic(path, json.dumps(data, indent=indent) + "\n")
