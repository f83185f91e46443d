"""Exceptions raised at the library boundary, in two families.

:class:`InputError` (also a ``ValueError``): the caller's input is wrong, and the same call fails
again; the command-line tools exit 2. :class:`RunFailure` (also a ``RuntimeError``): a computation
on valid input did not succeed (no convergence, divergence, a failed write); they exit 1. Both
derive from :class:`ContgraspError`. :class:`ContactValidityError` is an input error: the contact
kinematics are a deterministic function of the caller's initial state and curvature profile.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "ContgraspError",
    "InputError",
    "RunFailure",
    "FailedResult",
    "InvalidParameterError",
    "InvalidBoundaryError",
    "NotClosedError",
    "SelfIntersectionError",
    "DegenerateBoundaryError",
    "ContactValidityError",
    "MissingDependencyError",
    "WriteError",
    "IntegrationError",
    "output_error",
    "refuse_ignored",
    "one_line",
    "exit_code",
    "interruption",
]


def one_line(exc: BaseException) -> str:
    """The exception's message on one line (a parser's multi-line message joined with ' | '),
    as the command-line tools print it."""
    return " | ".join(line.strip() for line in str(exc).splitlines() if line.strip())


def interruption(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C behind ``exc``: the KeyboardInterrupt in its chain of causes, or None.

    A SIGINT handled while a compiled (numba) function boxes its result is not raised by the
    call: it comes out as ``SystemError("CPUDispatcher(...) returned a result with an exception
    set")`` caused by the KeyboardInterrupt (seen when ``frames_nodes`` was interrupted). That is
    a stop, not a failure of the computation."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return None


class ContgraspError(Exception):
    """Root of every error :mod:`contgrasp_core` and :mod:`contgrasp_ros` raise on purpose;
    every concrete class is in exactly one of :class:`InputError` and :class:`RunFailure`."""


class InputError(ContgraspError, ValueError):
    """The input is wrong (exit code 2 in the command-line tools); the message says what was
    wrong and the valid range."""


class RunFailure(ContgraspError, RuntimeError):
    """A computation on valid input failed (exit code 1 in the command-line tools)."""


class FailedResult(RunFailure):
    """A computation that ended with a result, but not the one asked for (no optimal grasp, a
    recording that does not recompute): ``result`` is what it reached, which the command-line
    tools print before the one error line."""

    def __init__(self, message: str, result: dict[str, Any]) -> None:
        super().__init__(message)
        self.result = result


def exit_code(exc: BaseException) -> int:
    """The command-line tools' exit code for an error: 2 for bad input (:class:`InputError`),
    1 for anything else (:class:`RunFailure`, an unexpected exception)."""
    return 2 if isinstance(exc, InputError) else 1


class InvalidParameterError(InputError):
    """A scalar or array parameter is outside its valid range or has the wrong shape."""


class InvalidBoundaryError(InputError):
    """An object boundary cannot be built from the given data."""


class NotClosedError(InvalidBoundaryError):
    """The given points do not form a closed curve (first and last point differ)."""


class SelfIntersectionError(InvalidBoundaryError):
    """The given polygon or the smoothed curve through it crosses itself."""


class DegenerateBoundaryError(InvalidBoundaryError):
    """Too few distinct points, zero enclosed area, or non-finite coordinates."""


class ContactValidityError(InputError):
    """The contact kinematics left their valid region (paper Sec. II-C).

    Valid states satisfy ``rho > 0``, ``0 < alpha < pi`` and ``1 + rho * kappa_o > 0``
    (eq. (7)). ``s`` is the arm arclength where validity was lost and
    ``condition`` names the violated inequality. An input error also when raised mid-
    integration: the initial state and curvature profile given determine the path (module
    docstring).
    """

    def __init__(self, message: str, *, s: float, condition: str) -> None:
        super().__init__(message)
        self.s = float(s)
        self.condition = condition


class MissingDependencyError(InputError):
    """A command needs an optional dependency that is not installed (the ROS layer, Dask); the
    message names the missing module and what to install. An input error: the same command fails
    again until the environment changes, and the command-line tools exit with code 2."""


class IntegrationError(RunFailure):
    """An ODE integrator stopped without reaching the end of the interval (step size
    underflow and the like) although the state stayed admissible."""


class WriteError(RunFailure):
    """An output file could not be written although its name was valid (disk full, file size
    limit, permission, I/O error); the message names the file and the operating system's reason."""


def output_error(what: str, exc: BaseException) -> ContgraspError:
    """The error for a failed write of ``what`` (e.g. ``"the figure out.png"``): an
    :class:`OSError` is a :class:`WriteError`; anything else (matplotlib's ``ValueError`` for
    a format it cannot write) is an :class:`InvalidParameterError`. Raise it ``from exc``."""
    if isinstance(exc, OSError):
        return WriteError(f"cannot write {what}: {exc.strerror or exc}")
    return InvalidParameterError(f"cannot write {what}: {exc}")


def refuse_ignored(names: list[str], where: str, needs: str) -> None:
    """Refuse settings that would pass silently: ``names`` (those given, or changed from their
    defaults) do nothing ``where`` (``"under --law paper"``) and take ``needs`` (``"--law hold or reactive"``).
    An :class:`InvalidParameterError` in one line naming them all; nothing when ``names`` is empty."""
    if names:
        one = len(names) == 1
        raise InvalidParameterError(f"{', '.join(names)} {'does' if one else 'do'} nothing {where}: "
                                    f"{'it needs' if one else 'they need'} {needs}")
