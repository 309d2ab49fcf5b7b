"""Deterministic dataset archives and their safe extraction.

`pack_build` writes a .tar.gz whose bytes depend only on the files: members sorted by path, mtime 0,
owner root/root with empty names, modes 0644/0755, and a gzip header without name or timestamp.

`safe_extract` accepts only plain files and directories with relative paths that stay inside the
destination (no absolute paths, no `..`, no symlinks, hard links or devices), checks every member
before writing anything, extracts into a temporary sibling and renames it into place.
"""

from __future__ import annotations

import gzip
import io
import os
import shutil
import tarfile
import tempfile
import zlib
from pathlib import Path, PurePosixPath

from hexbench.errors import HexbenchError


class ArchiveError(HexbenchError):
    """An archive that is damaged or unsafe to extract (message: one line naming the problem)."""


def pack_build(build_dir: Path, archive_path: Path, root_name: str) -> Path:
    """Pack every file under `build_dir` into `archive_path` under the top-level folder `root_name`."""
    build_dir, archive_path = Path(build_dir), Path(archive_path)
    files = sorted(p for p in build_dir.rglob("*") if p.is_file())
    dirs = sorted({q for p in files for q in p.relative_to(build_dir).parents if q != Path(".")})
    archive_path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{archive_path.name}.", dir=archive_path.parent)
    try:
        with os.fdopen(fd, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz, \
                tarfile.open(fileobj=gz, mode="w", format=tarfile.PAX_FORMAT) as tar:
            tar.addfile(_dir_info(root_name))
            for d in dirs:
                tar.addfile(_dir_info(f"{root_name}/{d.as_posix()}"))
            for path in files:
                data = path.read_bytes()
                info = tarfile.TarInfo(f"{root_name}/{path.relative_to(build_dir).as_posix()}")
                info.size, info.mode, info.mtime = len(data), 0o644, 0
                info.uid = info.gid = 0
                info.uname = info.gname = ""
                tar.addfile(info, io.BytesIO(data))
        os.chmod(tmp, 0o644)
        os.replace(tmp, archive_path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return archive_path


def _dir_info(name: str) -> tarfile.TarInfo:
    info = tarfile.TarInfo(name)
    info.type, info.mode, info.mtime = tarfile.DIRTYPE, 0o755, 0
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    return info


def check_member(member: tarfile.TarInfo) -> None:
    """Raise ArchiveError if `member` is not a plain file or directory at a safe relative path."""
    name = member.name
    path = PurePosixPath(name)
    if name.startswith(("/", "\\")) or path.is_absolute() or (len(name) > 1 and name[1] == ":"):
        raise ArchiveError(f"unsafe archive: absolute path {name!r}")
    if ".." in path.parts or "\\" in name:
        raise ArchiveError(f"unsafe archive: path {name!r} leaves the destination")
    if member.issym() or member.islnk():
        raise ArchiveError(f"unsafe archive: link {name!r} -> {member.linkname!r}; only files and folders are allowed")
    if not (member.isfile() or member.isdir()):
        raise ArchiveError(f"unsafe archive: {name!r} is not a plain file or folder")


def safe_extract(archive_path: Path, dest_dir: Path) -> Path:
    """Extract `archive_path` (.tar.gz) so that its contents appear at `dest_dir`; return `dest_dir`."""
    archive_path, dest_dir = Path(archive_path), Path(dest_dir)
    dest_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dest_dir.name}.tmp-", dir=dest_dir.parent))
    try:
        try:
            with tarfile.open(archive_path, mode="r:gz") as tar:
                members = tar.getmembers()  # reads to the end: a truncated archive fails here
                for m in members:
                    check_member(m)
                tar.extractall(tmp, members=members, filter="data")
        except (tarfile.TarError, EOFError, zlib.error, gzip.BadGzipFile, OSError) as err:
            raise ArchiveError(f"damaged archive {archive_path.name}: {type(err).__name__}: {err}") from None
        tops = [p for p in tmp.iterdir()]
        root = tops[0] if len(tops) == 1 and tops[0].is_dir() else tmp
        if dest_dir.exists():
            shutil.rmtree(dest_dir)
        os.replace(root, dest_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return dest_dir
