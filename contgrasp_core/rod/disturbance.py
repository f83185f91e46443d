"""Disturbances: a wrench on the movable object over time (beyond the paper).

A :class:`Disturbance` is a step, a ramp or a pulse of the wrench ``(fx, fy, torque)`` (N, N, N m;
force at the centroid) from ``start`` (s of simulated time). The loop holds the wrench of the
start of each control period over that period, so a scripted disturbance gives the same run in
the core loop and in the ROS graph; :class:`WrenchInput` adds a user's live inputs, each taking
effect from the next period on. docs/ros.md, "A movable object".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.errors import InvalidParameterError

__all__ = ["KINDS", "Disturbance", "WrenchInput", "wrench_array"]

KINDS = ("step", "ramp", "pulse")


def wrench_array(name: str, value: object) -> NDArray[np.float64]:
    """``value`` as a wrench (3,) (fx, fy, torque), or :class:`InvalidParameterError` naming ``name``."""
    try:
        w = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"{name} must be three numbers (fx, fy, torque), got {value!r}") from exc
    if w.shape != (3,) or not np.all(np.isfinite(w)):
        raise InvalidParameterError(f"{name} must be three finite numbers (fx, fy, torque), got {value!r}")
    return w


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
        w = wrench_array("disturbance wrench", self.wrench)
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


class WrenchInput:
    """The wrench on the object per control period: the scripted disturbance (if any), plus the
    latest held wrench (:meth:`hold`: stays until replaced; zeros release it), plus every
    disturbance applied so far (:meth:`apply`: a step, ramp or pulse that starts with the next
    period). Inputs wait until :meth:`freeze` fixes the wrench of the next period's state."""

    def __init__(self, scripted: Disturbance | None = None) -> None:
        self.scripted = scripted
        self.reset()

    def reset(self) -> None:
        """Forget the live inputs (a new run); the scripted disturbance stays."""
        self.held = np.zeros(3)
        self.applied: list[Disturbance] = []
        self._pending_held: NDArray[np.float64] | None = None
        self._pending: list[tuple[str, tuple[float, float, float], float]] = []
        self._frozen: tuple[int, NDArray[np.float64] | None] | None = None

    def hold(self, wrench: NDArray[np.float64]) -> None:
        """Hold ``wrench`` (3,) from the next period on, until another replaces it."""
        self._pending_held = wrench_array("a held wrench", wrench).copy()

    def apply(self, kind: str, wrench: tuple[float, float, float], duration: float = 0.0) -> None:
        """Apply a step, ramp or pulse (:class:`Disturbance`) starting with the next period; the
        values are checked now (:class:`InvalidParameterError`)."""
        Disturbance(kind, wrench, 0.0, duration)
        self._pending.append((kind, wrench, duration))

    def next_step(self, k: int) -> int:
        """The first period an input received now acts on, the loop being at step ``k``."""
        return k + 1 if self._frozen is not None and self._frozen[0] == k else k

    def freeze(self, k: int, t: float) -> NDArray[np.float64] | None:
        """The wrench (3,) held over period ``k``, which starts at ``t`` (None: none at all, the
        scripted-free run's exact path); the waiting inputs take effect here. The same for
        repeated calls with the same ``k``."""
        if self._frozen is not None and self._frozen[0] == k:
            return self._frozen[1]
        if self._pending_held is not None:
            self.held, self._pending_held = self._pending_held, None
        self.applied += [Disturbance(kind, w, t, d) for kind, w, d in self._pending]
        self._pending.clear()
        total = None if self.scripted is None else self.scripted.wrench_at(t)
        for extra in (self.held if np.any(self.held) else None, *(d.wrench_at(t) for d in self.applied)):
            if extra is not None:
                total = extra.copy() if total is None else total + extra
        self._frozen = (k, total)
        return total
