"""Input checks shared by the public entry points (private helpers).

Every helper turns a value of the wrong Python type (a string, None, a nested list where a
number is expected) into the same :class:`~contgrasp_core.errors.ContgraspError` subclass as an
out-of-range value, with a message naming the parameter and its valid range.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import ContgraspError, InvalidParameterError

__all__ = ["real", "integer", "float_array", "instance", "MAX_NODES"]

MAX_NODES = 1_000_000
"""Largest grid size accepted anywhere (a grid of more nodes does not fit the banded solvers'
memory and is never needed: the paper uses 500)."""


def real(
    name: str,
    value: Any,
    *,
    lo: float = -np.inf,
    hi: float = np.inf,
    lo_open: bool = False,
    hi_open: bool = False,
    error: type[ContgraspError] = InvalidParameterError,
) -> float:
    """``value`` as a finite float in the interval [lo, hi] (ends open when asked)."""
    try:
        if np.ndim(value) != 0:
            raise TypeError("not a scalar")
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be a number, got {value!r}") from exc
    ok = np.isfinite(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        raise error(f"{name} must be a finite number{_range(lo, hi, lo_open, hi_open)}, got {value!r}")
    return v


def _range(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    if np.isinf(lo) and np.isinf(hi):
        return ""
    if np.isinf(hi):
        return f" {'>' if lo_open else '>='} {lo:g}"
    if np.isinf(lo):
        return f" {'<' if hi_open else '<='} {hi:g}"
    return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def integer(name: str, value: Any, *, lo: int, hi: int, error: type[ContgraspError] = InvalidParameterError) -> int:
    """``value`` as an int in [lo, hi]; integral floats (3.0) are accepted, 2.5 and bools are not."""
    try:
        if np.ndim(value) != 0 or isinstance(value, bool | np.bool_):
            raise TypeError("not an integer")
        v = float(value)
        ok = np.isfinite(v) and v == int(v)
    except (TypeError, ValueError, OverflowError) as exc:
        raise error(f"{name} must be an integer in [{lo}, {hi}], got {value!r}") from exc
    if not ok or not lo <= int(v) <= hi:
        raise error(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(v)


def instance(name: str, value: Any, cls: type) -> None:
    """Raise InvalidParameterError unless ``value`` is a ``cls`` (e.g. a Boundary, not a string)."""
    if not isinstance(value, cls):
        raise InvalidParameterError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")


def float_array(name: str, value: Any, *, error: type[ContgraspError] = InvalidParameterError) -> NDArray[np.float64]:
    """``np.asarray(value, dtype=float)``; a ragged or non-numeric value raises ``error``."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be numeric array data, got {type(value).__name__}: {exc}") from exc
