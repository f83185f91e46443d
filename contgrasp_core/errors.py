"""Exceptions raised at the library boundary.

Every exception is a ``ValueError`` subclass so that generic callers can catch bad input
uniformly, while the specific classes let scripts react to what exactly was wrong.
The message always says what was wrong and what the valid range is.
"""

from __future__ import annotations


def one_line(exc: BaseException) -> str:
    """The exception's message on one line (a parser's multi-line message joined with ' | '),
    as the command-line tools print it."""
    return " | ".join(line.strip() for line in str(exc).splitlines() if line.strip())


class ContgraspError(ValueError):
    """Base class of every error raised by :mod:`contgrasp_core` for bad input or state."""


class InvalidParameterError(ContgraspError):
    """A scalar or array parameter is outside its valid range or has the wrong shape."""


class InvalidBoundaryError(ContgraspError):
    """An object boundary cannot be built from the given data."""


class NotClosedError(InvalidBoundaryError):
    """The given points do not form a closed curve (first and last point differ)."""


class SelfIntersectionError(InvalidBoundaryError):
    """The given polygon or the smoothed curve through it crosses itself."""


class DegenerateBoundaryError(InvalidBoundaryError):
    """Too few distinct points, zero enclosed area, or non-finite coordinates."""


class ContactValidityError(ContgraspError):
    """The contact kinematics left their valid region (paper Sec. II-C).

    Valid states satisfy ``rho > 0``, ``0 < alpha < pi`` and ``1 + rho * kappa_o > 0``
    (eq. object_speed). ``s`` is the arm arclength where validity was lost and
    ``condition`` names the violated inequality.
    """

    def __init__(self, message: str, *, s: float, condition: str) -> None:
        super().__init__(message)
        self.s = float(s)
        self.condition = condition
