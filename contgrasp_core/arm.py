"""Continuum arm geometry: length, radius profile, base pose, and shape from curvature.

Paper Sec. II-A, eq. kinematics: ``dr/ds = a = (cos theta, sin theta)``, ``dtheta/ds = kappa``
for ``s in [0, L]``, with the base pose ``(r(0), theta(0)) = (r0, theta0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from .errors import InvalidParameterError

__all__ = ["BasePose", "Arm", "ArmShape", "arclength_grid", "curvature_spline", "shape_from_curvature"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True)
class BasePose:
    """Arm base position ``(x, y)`` and heading ``theta`` (radians, from the x axis)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def __post_init__(self) -> None:
        if not all(np.isfinite([self.x, self.y, self.theta])):
            raise InvalidParameterError(f"base pose must be finite, got {self}")


@dataclass(frozen=True)
class Arm:
    """Arm of length ``length`` with a radius tapering linearly from base to tip.

    ``radius_tip=None`` means a constant radius ``radius_base``.
    """

    length: float
    radius_base: float
    radius_tip: float | None = None

    def __post_init__(self) -> None:
        if not np.isfinite(self.length) or self.length <= 0.0:
            raise InvalidParameterError(f"arm length must be > 0, got {self.length!r}")
        if not np.isfinite(self.radius_base) or self.radius_base <= 0.0:
            raise InvalidParameterError(f"base radius must be > 0, got {self.radius_base!r}")
        tip = self.radius_tip
        if tip is not None and (not np.isfinite(tip) or tip <= 0.0):
            raise InvalidParameterError(f"tip radius must be > 0, got {tip!r}")

    @classmethod
    def paper_tapered(cls, length: float) -> Arm:
        """Paper Sec. III-B: radius L/20 at the base tapering linearly to L/200 at the tip."""
        return cls(length, length / 20.0, length / 200.0)

    def radius(self, s: ArrayLike) -> NDArray[np.float64]:
        """Cross-section radius r(s), linear in s."""
        ss = np.asarray(s, dtype=float)
        tip = self.radius_base if self.radius_tip is None else self.radius_tip
        return self.radius_base + (tip - self.radius_base) * ss / self.length

    def grid(self, nodes: int) -> NDArray[np.float64]:
        """``nodes`` equally spaced arclengths from 0 to L."""
        return arclength_grid(self.length, nodes)


@dataclass(frozen=True)
class ArmShape:
    """Arm centreline ``r`` (n, 2) and tangent angle ``theta`` (n,) at arclengths ``s`` (n,)."""

    s: NDArray[np.float64]
    r: NDArray[np.float64]
    theta: NDArray[np.float64]

    @property
    def tangent(self) -> NDArray[np.float64]:
        """Unit tangent a(s) = (cos theta, sin theta)."""
        return np.stack([np.cos(self.theta), np.sin(self.theta)], axis=-1)


def arclength_grid(length: float, nodes: int) -> NDArray[np.float64]:
    """Equally spaced grid of ``nodes`` >= 2 points on [0, length]."""
    if int(nodes) != nodes or nodes < 2:
        raise InvalidParameterError(f"nodes must be an integer >= 2, got {nodes!r}")
    if not np.isfinite(length) or length <= 0.0:
        raise InvalidParameterError(f"length must be > 0, got {length!r}")
    return np.linspace(0.0, float(length), int(nodes))


def _check_grid(s: NDArray[np.float64]) -> None:
    if s.ndim != 1 or len(s) < 2 or not np.all(np.isfinite(s)) or np.any(np.diff(s) <= 0.0):
        raise InvalidParameterError("s must be a finite, strictly increasing 1-D grid of >= 2 points")


def curvature_spline(s: ArrayLike, kappa: ArrayLike) -> CubicSpline:
    """Cubic spline through curvature samples; the common interpolant of shape and ODE."""
    ss = np.asarray(s, dtype=float)
    kk = np.asarray(kappa, dtype=float)
    _check_grid(ss)
    if kk.shape != ss.shape or not np.all(np.isfinite(kk)):
        raise InvalidParameterError(
            f"kappa must be finite with the same shape as s {ss.shape}, got {kk.shape}"
        )
    return CubicSpline(ss, kk, bc_type="not-a-knot" if len(ss) > 3 else "natural")


def shape_from_curvature(
    s: ArrayLike, kappa: ArrayLike, base: BasePose = BasePose()
) -> ArmShape:
    """Integrate eq. kinematics from the base pose for curvature samples ``kappa`` on ``s``.

    The curvature is interpolated by a cubic spline; ``theta`` is its exact antiderivative
    and ``r`` is integrated with 8-point Gauss-Legendre quadrature on every grid cell, so the
    shape is fourth-order accurate in the grid spacing (not Euler). ``s[0]`` is the base.
    """
    ss = np.asarray(s, dtype=float)
    spline = curvature_spline(ss, kappa)
    theta_fn = spline.antiderivative()
    offset = base.theta - theta_fn(ss[0])
    theta = theta_fn(ss) + offset
    h = np.diff(ss)
    nodes = 0.5 * (ss[:-1] + ss[1:])[:, None] + 0.5 * h[:, None] * _GL_X[None, :]
    th_nodes = theta_fn(nodes) + offset
    dx = 0.5 * h * (np.cos(th_nodes) @ _GL_W)
    dy = 0.5 * h * (np.sin(th_nodes) @ _GL_W)
    r = np.empty((len(ss), 2))
    r[0] = (base.x, base.y)
    r[1:, 0] = base.x + np.cumsum(dx)
    r[1:, 1] = base.y + np.cumsum(dy)
    return ArmShape(s=ss, r=r, theta=theta)
