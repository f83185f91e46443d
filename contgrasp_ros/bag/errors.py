"""The errors a recording problem raises, in the two families of :mod:`contgrasp_core.errors`.

* :class:`BagInputError` (an :class:`~contgrasp_core.errors.InputError`, exit code 2): the
  recording given to read is missing, not MCAP, truncated, corrupt or undecodable; a writer
  option is out of range; the output path cannot name a new recording (it exists, or an
  existing part of it is not a folder).
* :class:`BagIOError` (a :class:`~contgrasp_core.errors.RunFailure`, exit code 1): the
  operating system failed a read or write of a valid recording or output path (disk full,
  file size limit, permission denied on the output, I/O error).

Catch :class:`BagError` for both.
"""

from __future__ import annotations

import errno

from contgrasp_core.errors import ContgraspError, InputError, RunFailure

__all__ = ["BagError", "BagInputError", "BagIOError", "read_error"]


class BagError(ContgraspError):
    """A recording cannot be written or read; the message says which file and why. Only its
    subclasses are raised."""


class BagInputError(BagError, InputError):
    """The recording, writer option or output path given is unusable (bad input)."""


class BagIOError(BagError, RunFailure):
    """Reading or writing a recording failed in the operating system (a run failure)."""


# errno values that say the path given does not name a readable recording (bad input);
# any other OSError while reading (EIO, ENOMEM, ...) is a failure of the run.
_PATH_ERRNOS = frozenset({errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.EACCES, errno.EPERM, errno.ELOOP,
                          errno.ENAMETOOLONG, errno.ENXIO})


def read_error(message: str, exc: OSError) -> BagError:
    """The error for an OSError while reading a recording: :class:`BagInputError` when the
    path is wrong (missing, not a file, no permission), else :class:`BagIOError`."""
    return (BagInputError if exc.errno in _PATH_ERRNOS else BagIOError)(message)
