"""Where a command writes, checked before the work (docs/cli.md, "Input limits").

A figure, a results file, a summary or a recording that cannot be written where it is named
should stop the command at once, not after minutes of computing. Permission bits do not tell
(root writes read-only folders, a read-only file system or ``/proc`` refuses everyone), so the
check tries: it creates and removes a probe file where the output would go.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .errors import InvalidParameterError

__all__ = ["check_output"]


def check_output(path: str | Path, option: str, *, folder: bool = False) -> Path:
    """``path`` as a :class:`~pathlib.Path` if the command can write it there: a file
    (``folder=False``; an existing one must be a file this process may write) or a folder
    (an existing one must be a directory it may create files in), below missing folders it
    may create (the nearest existing one takes a probe file). Otherwise an
    :class:`~contgrasp_core.errors.InvalidParameterError`, one line naming ``option`` and
    ``path``. Nothing is left behind."""
    if not str(path):
        raise InvalidParameterError(f"{option} needs a file name")
    p = Path(path)
    if p.exists() and p.is_dir() != folder:
        raise InvalidParameterError(f"{option} {path}: " + ("is a directory" if p.is_dir() else "exists and is not a directory"))
    nearest = next((d for d in (p, *p.parents) if d.exists()), Path("."))
    if not nearest.is_dir() and nearest != p:
        raise InvalidParameterError(f"{option} {path}: {nearest} is not a directory")
    existing_file = nearest == p and not folder
    try:
        if existing_file:
            open(p, "ab").close()  # (appending nothing changes nothing)
        else:
            fd, probe = tempfile.mkstemp(prefix=".contgrasp-probe-", dir=nearest)
            os.close(fd)
            os.remove(probe)
    except OSError as exc:
        what = "cannot write it" if existing_file else f"cannot create a file in {nearest}"
        raise InvalidParameterError(f"{option} {path}: {what} ({exc.strerror or exc})") from None
    return p
