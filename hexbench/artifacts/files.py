"""Hashing, bounded reads and atomic writes: the one place files are hashed, read from untrusted
folders and written whole or not at all.

A file that may come from someone else (a submitted run folder, a record, a controller's weights) is
read only if it is a plain file no larger than its format allows (`read_bytes_bounded`,
`read_json_bounded`, `sha256_file(..., max_bytes=)`): a pipe would make the read hang, a device
or a huge sparse file would make it never end. Anything else is one `InputError` line.

A write goes to a hidden temporary name beside the target and is renamed over it when complete, so
a reader never sees half a file. Any OS failure (read-only folder, a file where a folder should be,
a name too long, a full disk) removes the temporary file and becomes one `OutputError` line.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hexbench.errors import InputError, OutputError, os_reason

READ_BLOCK_BYTES = 1 << 20


def sha256_file(path: str | Path, max_bytes: int | None = None, what: str = "file") -> str:
    """The sha256 of a file's bytes; with `max_bytes`, of a plain file of at most that many bytes
    (InputError naming the `what` it should be otherwise, before anything is hashed)."""
    digest = hashlib.sha256()
    if max_bytes is None:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(READ_BLOCK_BYTES), b""):
                digest.update(block)
        return digest.hexdigest()
    for block in _plain_file_blocks(path, max_bytes, what):
        digest.update(block)
    return digest.hexdigest()


def read_bytes_bounded(path: str | Path, max_bytes: int, what: str = "file") -> bytes:
    """The bytes of `path` if it is a plain file of at most `max_bytes` bytes; InputError (one line
    naming the path and the `what` it should be) if it is missing, unreadable, a folder, a pipe, a
    device or a socket, or larger."""
    return b"".join(_plain_file_blocks(path, max_bytes, what))


def read_json_bounded(path: str | Path, max_bytes: int, what: str = "JSON file"):
    """`read_bytes_bounded`, parsed as JSON; InputError if it is not valid JSON (nesting too deep
    for the parser included)."""
    data = read_bytes_bounded(path, max_bytes, what)
    try:
        return json.loads(data)
    except (ValueError, RecursionError) as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        reason = "nested too deeply" if isinstance(e, RecursionError) else str(e).split("\n")[0][:200]
        raise InputError(f"{path}: not valid JSON ({reason})") from None


def file_kind(mode: int) -> str:
    """What a file of this `st_mode` is, in words: "a plain file", "a folder", "a pipe", "a device",
    "a socket" or "a special file"."""
    for test, kind in ((stat.S_ISREG, "a plain file"), (stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a pipe"),
                       (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "a special file"


def _plain_file_blocks(path: str | Path, max_bytes: int, what: str) -> Iterator[bytes]:
    """The blocks of a plain file of at most `max_bytes` bytes. Opened without blocking (opening a
    pipe to read would wait for a writer) and checked on the open descriptor, so what is read is
    what was checked; a file that grows past the bound while it is read is refused too."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise InputError(f"{path}: cannot be read ({os_reason(e)})") from None
    try:
        status = os.fstat(fd)
        if not stat.S_ISREG(status.st_mode):
            raise InputError(f"{path}: is {file_kind(status.st_mode)}; a {what} must be a plain file")
        if status.st_size > max_bytes:
            raise InputError(f"{path}: {status.st_size:,} bytes; a {what} has at most {max_bytes:,}")
        os.set_blocking(fd, True)
        total = 0
        while True:
            try:
                block = os.read(fd, READ_BLOCK_BYTES)
            except OSError as e:
                raise InputError(f"{path}: cannot be read ({os_reason(e)})") from None
            if not block:
                return
            total += len(block)
            if total > max_bytes:
                raise InputError(f"{path}: grew past {max_bytes:,} bytes while read; a {what} has at most {max_bytes:,}")
            yield block
    finally:
        os.close(fd)


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
