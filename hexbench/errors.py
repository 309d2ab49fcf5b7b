"""The one base class of hexbench's user-facing failures.

Every error a user can cause (a broken or hostile controller, a corrupt file, an unknown task, an
unwritable folder) is a `HexbenchError` whose message is one line naming the problem and, where
there are any, the valid choices. The CLI turns it into `error: <message>` and a non-zero exit.
"""

from __future__ import annotations


class HexbenchError(Exception):
    """A one-line, user-facing failure."""


class OutputError(HexbenchError):
    """A run's output folder or file cannot be written (read-only, not a folder, name too long, disk full)."""


class InputError(HexbenchError):
    """A file given to hexbench cannot be taken: missing, unreadable, not a plain file (a pipe or a
    device would make reading hang or never end), larger than its format allows, or malformed."""
