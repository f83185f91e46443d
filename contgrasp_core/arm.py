"""Continuum arm geometry: length, radius profile, base pose, and shape from curvature.

Paper Sec. II-A, eq. (1) (arm kinematics): ``dr/ds = a = (cos theta, sin theta)``, ``dtheta/ds = kappa``
for ``s in [0, L]``, with the base pose ``(r(0), theta(0)) = (r0, theta0)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import MAX_NODES, float_array, instance, integer, real
from .errors import InvalidParameterError

if TYPE_CHECKING:  # (imported where a spline is built: node processes that never build one start faster)
    from scipy.interpolate import CubicSpline

__all__ = ["BasePose", "Arm", "ArmShape", "arclength_grid", "curvature_spline", "shape_from_curvature"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True)
class BasePose:
    """Arm base position ``(x, y)`` and heading ``theta`` (radians, from the x axis)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "theta"):
            real(f"base pose {name}", getattr(self, name))


@dataclass(frozen=True)
class Arm:
    """Arm of length ``length`` with a radius tapering linearly from base to tip.

    ``radius_tip=None`` means a constant radius ``radius_base``.
    """

    length: float
    radius_base: float
    radius_tip: float | None = None

    def __post_init__(self) -> None:
        real("arm length", self.length, lo=0.0, lo_open=True)
        real("base radius", self.radius_base, lo=0.0, lo_open=True)
        if self.radius_tip is not None:
            real("tip radius", self.radius_tip, lo=0.0, lo_open=True)

    @classmethod
    def paper_tapered(cls, length: float) -> Arm:
        """Paper Sec. III-A: radius L/20 at the base tapering linearly to L/200 at the tip."""
        length = real("arm length", length, lo=0.0, lo_open=True)
        return cls(length, length / 20.0, length / 200.0)

    def radius(self, s: ArrayLike) -> NDArray[np.float64]:
        """Cross-section radius r(s), linear in s."""
        ss = float_array("s", s)
        if not np.all(np.isfinite(ss)):
            raise InvalidParameterError("arclengths s must be finite")
        tip = self.radius_base if self.radius_tip is None else self.radius_tip
        with np.errstate(over="ignore", invalid="ignore"):
            r = self.radius_base + (tip - self.radius_base) * ss / self.length
        if not np.all(np.isfinite(r)):
            raise InvalidParameterError(f"arclengths s lie too far outside [0, L = {self.length:.6g}]: the radius overflows")
        return r

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
    n = integer("nodes", nodes, lo=2, hi=MAX_NODES)
    length = real("length", length, lo=0.0, lo_open=True)
    return np.linspace(0.0, length, n)


def _check_grid(s: NDArray[np.float64]) -> None:
    if s.ndim != 1 or len(s) < 2 or not np.all(np.isfinite(s)) or np.any(np.diff(s) <= 0.0):
        raise InvalidParameterError("s must be a finite, strictly increasing 1-D grid of >= 2 points")


def curvature_spline(s: ArrayLike, kappa: ArrayLike) -> CubicSpline:
    """Cubic spline through curvature samples; the common interpolant of shape and ODE."""
    from scipy.interpolate import CubicSpline

    ss = float_array("s", s)
    kk = float_array("kappa", kappa)
    _check_grid(ss)
    if kk.shape != ss.shape or not np.all(np.isfinite(kk)):
        raise InvalidParameterError(
            f"kappa must be finite with the same shape as s {ss.shape}, got {kk.shape}"
        )
    try:
        with np.errstate(all="ignore"):  # (extreme spacings or values overflow: refused below)
            spline = CubicSpline(ss, kk, bc_type="not-a-knot" if len(ss) > 3 else "natural")
    except ValueError:  # (scipy refuses the overflowed slopes it computed itself)
        spline = None
    if spline is None or not np.all(np.isfinite(spline.c)):
        raise InvalidParameterError("the curvature samples are too extreme for a cubic spline (its coefficients "
                                    "overflow): check the units and the spacing of s")
    return spline


def shape_from_curvature(
    s: ArrayLike, kappa: ArrayLike, base: BasePose = BasePose()
) -> ArmShape:
    """Integrate the arm kinematics eq. (1) from the base pose for curvature samples ``kappa`` on ``s``.

    The curvature is interpolated by a cubic spline; ``theta`` is its exact antiderivative
    and ``r`` is integrated with 8-point Gauss-Legendre quadrature on every grid cell, so the
    shape is fourth-order accurate in the grid spacing (not Euler). ``s[0]`` is the base.
    """
    instance("base", base, BasePose)
    ss = float_array("s", s)
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
