"""Disturbances: a wrench on the movable object over time (beyond the paper).

A :class:`Disturbance` is a step, a ramp or a pulse of the wrench ``(fx, fy, torque)`` (N, N,
N m; force at the object's centroid) starting at ``start`` (s of simulated time):

* ``step``: the wrench from ``start`` on;
* ``ramp``: rising linearly from zero at ``start`` to the wrench at ``start + duration``, then held;
* ``pulse``: the wrench from ``start`` for ``duration`` seconds, then zero.

The closed loop holds the wrench of the start of each control period over that period (like
the couple), so a scripted disturbance gives the same run in the core loop and in the ROS graph.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.errors import InvalidParameterError

__all__ = ["KINDS", "Disturbance"]

KINDS = ("step", "ramp", "pulse")


@dataclass(frozen=True)
class Disturbance:
    """A scripted wrench on the object (module docstring)."""

    kind: str
    wrench: tuple[float, float, float]
    start: float = 0.0
    duration: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InvalidParameterError(f"disturbance kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        try:
            w = np.asarray(self.wrench, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidParameterError(f"disturbance wrench must be three numbers (fx, fy, torque), got {self.wrench!r}") from exc
        if w.shape != (3,) or not np.all(np.isfinite(w)):
            raise InvalidParameterError(f"disturbance wrench must be three finite numbers (fx, fy, torque), got {self.wrench!r}")
        object.__setattr__(self, "wrench", (float(w[0]), float(w[1]), float(w[2])))
        if not (np.isfinite(self.start) and self.start >= 0):
            raise InvalidParameterError(f"disturbance start must be a finite time >= 0 s, got {self.start!r}")
        if self.kind != "step" and not (np.isfinite(self.duration) and self.duration > 0):
            raise InvalidParameterError(f"a {self.kind}'s duration must be a finite time > 0 s, got {self.duration!r}")

    def wrench_at(self, t: float) -> NDArray[np.float64]:
        """The wrench (3,) at simulated time ``t`` (s)."""
        w = np.asarray(self.wrench)
        if t < self.start:
            return np.zeros(3)
        if self.kind == "ramp":
            return w * min((t - self.start) / self.duration, 1.0)
        if self.kind == "pulse" and t >= self.start + self.duration:
            return np.zeros(3)
        return w.copy()
