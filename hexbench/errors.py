"""The one base class of hexbench's user-facing failures.

Every error a user can cause (a broken or hostile controller, a corrupt file, an unknown task, an
unwritable folder) is a `HexbenchError` whose message is one line naming the problem and, where
there are any, the valid choices. The CLI turns it into `error: <message>` and a non-zero exit.
"""

from __future__ import annotations

import errno


class HexbenchError(Exception):
    """A one-line, user-facing failure."""


class OutputError(HexbenchError):
    """A run's output folder or file cannot be written (read-only, not a folder, name too long, disk full)."""


class InputError(HexbenchError):
    """A file given to hexbench cannot be taken: missing, unreadable, not a plain file (a pipe or a
    device would make reading hang or never end), larger than its format allows, or malformed."""


_REASONS = {errno.EROFS: "read-only file system", errno.EACCES: "permission denied", errno.EPERM: "permission denied",
            errno.ENOTDIR: "a path component is a file, not a folder", errno.EISDIR: "is a folder",
            errno.ENAMETOOLONG: "file name too long", errno.ENOSPC: "no space left on device",
            errno.EDQUOT: "disk quota exceeded", errno.EEXIST: "exists and is not a folder",
            errno.ENOENT: "no such file", errno.ELOOP: "too many levels of symbolic links"}


def os_reason(error: OSError) -> str:
    """An OSError in the words of a one-line failure: "no space left on device", "read-only file system"..."""
    return _REASONS.get(error.errno, error.strerror or " ".join(str(error).split())[:200] or type(error).__name__)
