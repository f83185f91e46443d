"""The one error a recording problem raises (unreadable, corrupt, truncated, unwritable)."""

from __future__ import annotations

from contgrasp_core.errors import ContgraspError

__all__ = ["BagError"]


class BagError(ContgraspError):
    """A recording cannot be written or read; the message says which file and why."""
