"""Object boundaries: smooth, simple, closed planar curves parameterised by arclength.

Paper Sec. II-B, eq. (2): ``d gamma / d s_o = t = (cos phi, sin phi)``, ``d phi / d s_o = kappa_o``.
Curves are traversed counter-clockwise (the object lies to the LEFT of the tangent), ``s_o``
runs over ``[0, L_o)`` and every evaluation accepts any real ``s_o`` (taken modulo ``L_o``;
the tangent angle is continued so that ``phi(s_o + L_o) = phi(s_o) + 2 pi``).

Every curve is built from a smooth ``2 pi``-periodic parametrisation ``c(t)`` whose
derivatives up to third order are known (analytically, or from a periodic quintic spline
for user points). Arclength ``s(t)`` is computed with 16-point Gauss-Legendre quadrature on
panels of ``t`` and inverted by Newton's method, so ``gamma(s_o)`` is arclength-parametrised
to rounding error; point, tangent angle, curvature and its derivative follow exactly from
the derivatives of ``c``.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast
from dataclasses import dataclass
from functools import cached_property
from math import comb

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import float_array, integer, real
from .errors import (
    DegenerateBoundaryError,
    InvalidParameterError,
    NotClosedError,
    SelfIntersectionError,
)

if TYPE_CHECKING:
    from scipy.interpolate import CubicSpline
    from scipy.spatial import cKDTree

__all__ = [
    "Boundary",
    "Projection",
    "circle",
    "ellipse",
    "fourier_polar",
    "deformed_circle",
    "from_points",
    "load_points",
    "wrap_arclength",
]

TWO_PI = 2.0 * np.pi


def wrap_arclength(ds: ArrayLike, length: float) -> NDArray[np.float64]:
    """A difference of arclengths on a closed curve of ``length``, wrapped into [-length/2, length/2)
    (s_o and s_o + L_o are the same point: compare arclengths with this, never directly)."""
    return np.mod(np.asarray(ds, dtype=float) + 0.5 * length, length) - 0.5 * length
CurveFn = Callable[[NDArray[np.float64], int], NDArray[np.float64]]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_N_TABLE = 4096  # samples of the curve used for inversion guesses and projection candidates
_MAX_TURNS = 1e15  # |s_o| <= _MAX_TURNS L_o: beyond it s_o mod L_o has no significant digits left
_MAX_COORD = 1e150  # query points farther out overflow squared distances
_MAX_HARMONICS = 512  # the 4096-sample tables resolve at most 8 samples per wavelength


@dataclass(frozen=True)
class Projection:
    """Closest points on the boundary of a set of query points.

    ``foot`` (n, 2) the closest boundary points gamma(s_o); ``s_o`` (n,) their arclength in
    ``[0, L_o)``; ``distance`` (n,) >= 0; ``signed_distance`` (n,) positive outside the object,
    negative inside; ``side`` (n,) +1 outside, -1 inside (0 exactly on the boundary);
    ``phi`` (n,) and ``kappa_o`` (n,) the tangent angle and curvature at the foot;
    ``normal_out`` (n, 2) the outward unit normal there (as in
    :class:`~contgrasp_core.rod.obstacle.ObstacleProjection`).
    """

    foot: NDArray[np.float64]
    s_o: NDArray[np.float64]
    distance: NDArray[np.float64]
    signed_distance: NDArray[np.float64]
    side: NDArray[np.int_]
    phi: NDArray[np.float64]
    kappa_o: NDArray[np.float64]

    @property
    def normal_out(self) -> NDArray[np.float64]:
        """Outward unit normal ``(sin phi, -cos phi)`` at the foot (n, 2): ``-n(s_o)``."""
        return np.stack([np.sin(self.phi), -np.cos(self.phi)], axis=-1)


def _rot(vec_cos_sin_shift: int, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """k-th derivative of (cos t, sin t) as an (n, 2) array."""
    shifted = t + vec_cos_sin_shift * np.pi / 2.0
    return np.stack([np.cos(shifted), np.sin(shifted)], axis=-1)


class Boundary:
    """A simple closed smooth planar curve, counter-clockwise, parameterised by arclength.

    Build one with :func:`circle`, :func:`ellipse`, :func:`deformed_circle`,
    :func:`fourier_polar` or :func:`from_points`; ``kind`` and ``params`` record how.

    The interpolants of the arclength tables and the KD-tree of the samples are built on first
    use (scipy.interpolate and scipy.spatial are imported then): a closed-form projection, as
    the ROS boundary sensor's on a circle, needs neither, and a node process starts faster.
    """

    def __init__(
        self,
        curve: CurveFn,
        breakpoints: ArrayLike,
        *,
        kind: str,
        params: dict[str, Any],
    ) -> None:
        self._c = curve
        self.kind = kind
        self.params = dict(params)
        bp = np.asarray(breakpoints, dtype=float)
        self._bp = bp
        # Cumulative arclength at the panel breakpoints (eq. (2): |dgamma/ds_o| = 1).
        panel_len = self._gauss_arclength(bp[:-1], bp[1:])
        self._S = np.concatenate([[0.0], np.cumsum(panel_len)])
        self.length = float(self._S[-1])
        if not np.isfinite(self.length) or self.length <= 0.0:
            raise DegenerateBoundaryError(f"boundary '{kind}' has non-positive length {self.length}")
        if not 1e-100 < self.length < 1e100:
            raise DegenerateBoundaryError(
                f"boundary '{kind}' has length {self.length:.3g}; supported sizes are 1e-100 .. 1e100 (choose units)"
            )
        t_tab = np.linspace(0.0, TWO_PI, _N_TABLE + 1)
        s_tab = self._s_of_t(t_tab)
        s_tab[-1] = self.length
        if not (np.all(np.isfinite(s_tab)) and np.all(np.diff(s_tab) > 0.0)):
            raise DegenerateBoundaryError(
                f"boundary '{kind}' cannot be parameterised by arclength in floating point "
                f"(length {self.length:.3g}): its size is out of range or its speed vanishes"
            )
        self._s_tab, self._t_tab = s_tab, t_tab
        d1 = curve(t_tab, 1)
        phi_tab = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
        turning = phi_tab[-1] - phi_tab[0]
        if abs(turning - TWO_PI) > 1e-6:
            raise SelfIntersectionError(
                f"boundary '{kind}' has total tangent turning {turning / TWO_PI:.6f} x 2 pi; "
                "a simple counter-clockwise closed curve turns exactly once (+2 pi)"
            )
        self._phi_tab = phi_tab
        self._tab_t = t_tab[:-1]

    @cached_property
    def _t_of_s_guess(self) -> CubicSpline:
        """t(s) interpolated through the 4097-sample table (the start of :meth:`_t_of_s`'s Newton)."""
        from scipy.interpolate import CubicSpline

        return CubicSpline(self._s_tab, self._t_tab)

    @cached_property
    def _phi_ref(self) -> CubicSpline:
        """The continuous tangent angle phi(s) interpolated through the table (branch reference)."""
        from scipy.interpolate import CubicSpline

        return CubicSpline(self._s_tab, self._phi_tab)

    @cached_property
    def _tree(self) -> cKDTree:
        """KD-tree of the 4096 curve samples (candidates of the general closest-point search)."""
        from scipy.spatial import cKDTree

        return cKDTree(self._c(self._tab_t, 0))

    @staticmethod
    def load_table_modules() -> None:
        """Import what :meth:`prepare` builds its tables with (scipy.interpolate and
        scipy.spatial: ~0.3 s once per process), so that preparing a boundary later takes ~1 ms:
        a node that prepares each object it receives does this at start-up, since an object can
        arrive while a run is starting, when 0.3 s of CPU delays the loop's first steps."""
        import scipy.interpolate  # noqa: F401
        import scipy.spatial  # noqa: F401

    def prepare(self) -> Boundary:
        """Build the lazily made interpolants and search tree now (importing scipy.interpolate
        and scipy.spatial, ~0.3-0.6 s the first time in a process) rather than on the first
        geometric query; a node does this when an object arrives so that the first state it
        processes is not late. Returns the boundary."""
        for table in ("_t_of_s_guess", "_phi_ref", "_tree"):
            getattr(self, table)
        return self

    # ------------------------------------------------------------------ arclength maps
    def _arclengths(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """``s_o`` as a float array; every value finite with ``|s_o| <= 1e15 L_o``."""
        s = float_array("s_o", s_o)
        if not np.all(np.abs(s) <= _MAX_TURNS * self.length):
            raise InvalidParameterError(
                f"boundary arclengths s_o must be finite with |s_o| <= {_MAX_TURNS:.0e} L_o "
                f"(L_o = {self.length:.6g}); got NaN, infinite or out-of-range values"
            )
        return s

    def _speed(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.hypot(*self._c(t, 1).T)

    def _gauss_arclength(self, a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        half = 0.5 * (b - a)
        nodes = 0.5 * (a + b)[:, None] + half[:, None] * _GL_X[None, :]
        speed = self._speed(nodes.ravel()).reshape(nodes.shape)
        return half * (speed @ _GL_W)

    def _s_of_t(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        j = np.clip(np.searchsorted(self._bp, t, side="right") - 1, 0, len(self._bp) - 2)
        return self._S[j] + self._gauss_arclength(self._bp[j], t)

    def _t_of_s(self, s_o: ArrayLike) -> NDArray[np.float64]:
        s = np.mod(np.asarray(s_o, dtype=float).ravel(), self.length)
        t = np.clip(self._t_of_s_guess(s), 0.0, TWO_PI)
        for _ in range(4):  # Newton on s(t) = s; the spline guess is already ~1e-9 accurate
            err = self._s_of_t(t) - s
            t = np.clip(t - err / self._speed(t), 0.0, TWO_PI)
            if np.all(np.abs(err) <= 1e-11 * self.length):
                break
        return t

    # ------------------------------------------------------------------ geometry at s_o
    def point(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """gamma(s_o), shape ``s_o.shape + (2,)``."""
        s = self._arclengths(s_o)
        return self._c(self._t_of_s(s).ravel(), 0).reshape(s.shape + (2,))

    def _phi(self, t: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Continuous tangent angle at parameters ``t`` whose arclengths are ``s`` (same shape)."""
        d1 = self._c(t.ravel(), 1)
        raw = np.arctan2(d1[:, 1], d1[:, 0]).reshape(s.shape)
        ref = self._phi_ref(np.mod(s, self.length))
        phi = ref + (np.mod(raw - ref + np.pi, TWO_PI) - np.pi)
        return phi + TWO_PI * np.floor(s / self.length)

    def _kappa(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        d1, d2 = self._c(t, 1), self._c(t, 2)
        cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        return cross / np.hypot(*d1.T) ** 3

    def tangent_angle(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """Continuous tangent angle phi(s_o) (eq. (2)), ``phi(s + L_o) = phi(s) + 2 pi``."""
        s = self._arclengths(s_o)
        return self._phi(self._t_of_s(s), s)

    def tangent(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """Unit tangent t(s_o) = (cos phi, sin phi)."""
        phi = self.tangent_angle(s_o)
        return np.stack([np.cos(phi), np.sin(phi)], axis=-1)

    def normal(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """Unit normal n(s_o) = R(pi/2) t(s_o); it points INTO the object (CCW curve)."""
        phi = self.tangent_angle(s_o)
        return np.stack([-np.sin(phi), np.cos(phi)], axis=-1)

    def curvature(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """kappa_o(s_o) = d phi / d s_o (eq. (2)); positive on convex parts."""
        s = self._arclengths(s_o)
        return self._kappa(self._t_of_s(s)).reshape(s.shape)

    def curvature_with_derivative(
        self, s_o: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(kappa_o, d kappa_o / d s_o) with one arclength inversion.

        The derivative is needed by exact gradients in which the control moves the shadow
        point s_o (and hence kappa_o(s_o)).
        """
        s = self._arclengths(s_o)
        t = self._t_of_s(s)
        d1, d2, d3 = self._c(t, 1), self._c(t, 2), self._c(t, 3)
        sp2 = np.sum(d1 * d1, axis=1)
        cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        cross3 = d1[:, 0] * d3[:, 1] - d1[:, 1] * d3[:, 0]
        kappa = cross / sp2**1.5
        dkdt = (cross3 * sp2 - 3.0 * cross * np.sum(d1 * d2, axis=1)) / sp2**2.5
        return kappa.reshape(s.shape), (dkdt / np.sqrt(sp2)).reshape(s.shape)

    def curvature_derivative(self, s_o: ArrayLike) -> NDArray[np.float64]:
        """d kappa_o / d s_o."""
        return self.curvature_with_derivative(s_o)[1]

    def sample(self, n: int = 512) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``n`` points equally spaced in arclength: (s_o, gamma(s_o))."""
        s = np.linspace(0.0, self.length, integer("n", n, lo=0, hi=10_000_000), endpoint=False)
        return s, self.point(s)

    # ------------------------------------------------------------------ closest point
    def project(self, points: ArrayLike, *, candidates: int = 4) -> Projection:
        """Closest boundary point of each query point (vectorised).

        The ``candidates`` nearest of 4096 curve samples seed Newton iterations on
        ``(c(t) - q) . c'(t) = 0`` (steps limited to two sample spacings); the best refined
        candidate wins, so non-convex boundaries get the global closest point. A circle is
        projected in closed form and an ellipse by an exact one-dimensional root bracketing
        (same results to rounding, ~50x / ~10x faster; ``candidates`` is irrelevant there).
        """
        q = float_array("points", points)
        if q.ndim != 2 or q.shape[1] != 2 or not np.all(np.isfinite(q)):
            raise InvalidParameterError(f"points must be a finite (n, 2) array, got shape {q.shape}")
        if np.any(np.abs(q) > _MAX_COORD):
            raise InvalidParameterError(f"points must have coordinates within +-{_MAX_COORD:.0e}")
        k = min(integer("candidates", candidates, lo=1, hi=1_000_000), len(self._tab_t))
        if len(q) == 0:
            e = np.zeros(0)
            return Projection(np.zeros((0, 2)), e, e, e, np.zeros(0, dtype=int), e, e)
        if self.kind == "circle":
            return self._project_circle(q)
        if self.kind == "ellipse":
            return self._project_ellipse(q)
        return self._project_search(q, k)

    def _project_search(self, q: NDArray[np.float64], k: int) -> Projection:
        """The general closest-point search of :meth:`project` (``k`` candidates per query)."""
        _, idx = self._tree.query(q, k=k)
        idx = np.asarray(idx).reshape(len(q), k)
        h = TWO_PI / _N_TABLE
        qq = np.repeat(q, k, axis=0)
        t = self._refine(qq, self._tab_t[idx.ravel()], h)
        c = self._c(t, 0)
        dist = np.hypot(*(c - qq).T).reshape(len(q), k)
        best = np.argmin(dist, axis=1)
        rows = np.arange(len(q))
        t_best = t.reshape(len(q), k)[rows, best]
        foot = c.reshape(len(q), k, 2)[rows, best]
        d = dist[rows, best]
        d1 = self._c(t_best, 1)
        rel = q - foot
        cross = d1[:, 0] * rel[:, 1] - d1[:, 1] * rel[:, 0]  # > 0: query on the left = inside
        side = -np.sign(cross).astype(int)
        s_o = np.mod(self._s_of_t(t_best), self.length)
        s_o[s_o >= self.length] = 0.0  # mod of a tiny negative rounds to L_o: the seam is s_o = 0
        return Projection(
            foot=foot,
            s_o=s_o,
            distance=d,
            signed_distance=side * d,
            side=side,
            phi=self._phi(t_best, s_o),
            kappa_o=self._kappa(t_best),
        )

    def _project_circle(self, q: NDArray[np.float64]) -> Projection:
        """:meth:`project` for a circle in closed form: the foot is along the ray from the centre
        (the parameter ``t`` Newton converges to is the query's polar angle; a query at the centre
        gets ``t = 0``), ``s_o = R t``, ``phi = t + pi/2``, ``kappa_o = 1/R``. Same quantities,
        computed the same way from ``t``, as the general path (agrees with it to rounding; tested)."""
        R = float(self.params["R"])
        c0 = np.asarray(self.params["center"], dtype=float)
        rel_c = q - c0
        t = np.mod(np.arctan2(rel_c[:, 1], rel_c[:, 0]), TWO_PI)
        t[t >= TWO_PI] = 0.0  # mod of a tiny negative rounds to 2 pi: the seam is t = 0
        cs, sn = np.cos(t), np.sin(t)
        foot = np.empty_like(q)
        foot[:, 0] = R * cs + c0[0]
        foot[:, 1] = R * sn + c0[1]
        rel = q - foot
        d = np.hypot(rel[:, 0], rel[:, 1])
        cross = -R * sn * rel[:, 1] - R * cs * rel[:, 0]  # c'(t) x (q - foot) > 0: inside
        side = -np.sign(cross).astype(int)
        s_o = np.mod(R * t, self.length)
        s_o[s_o >= self.length] = 0.0
        return Projection(foot=foot, s_o=s_o, distance=d, signed_distance=side * d, side=side,
                          phi=t + 0.5 * np.pi, kappa_o=np.full(len(q), 1.0 / R))

    def _project_ellipse(self, q: NDArray[np.float64]) -> Projection:
        """:meth:`project` for an ellipse: the closest point's parameter ``t`` by Eberly's
        root bracketing in the ellipse's frame (:func:`contgrasp_core._geometry.ellipse_parameters`,
        global and exact to rounding for every query, no candidates needed), then foot, arclength,
        tangent angle, curvature and side from ``t`` exactly as the general path does."""
        from ._geometry import ellipse_parameters

        a_, b_ = float(self.params["a"]), float(self.params["b"])
        ang = float(self.params["angle"])
        rel_c = q - np.asarray(self.params["center"], dtype=float)
        ca, sa = np.cos(ang), np.sin(ang)
        local = np.empty_like(q)
        local[:, 0] = ca * rel_c[:, 0] + sa * rel_c[:, 1]
        local[:, 1] = -sa * rel_c[:, 0] + ca * rel_c[:, 1]
        t_best = ellipse_parameters(local, a_, b_)
        foot = self._c(t_best, 0)
        rel = q - foot
        d = np.hypot(rel[:, 0], rel[:, 1])
        d1 = self._c(t_best, 1)
        cross = d1[:, 0] * rel[:, 1] - d1[:, 1] * rel[:, 0]  # > 0: query on the left = inside
        side = -np.sign(cross).astype(int)
        s_o = np.mod(self._s_of_t(t_best), self.length)
        s_o[s_o >= self.length] = 0.0
        return Projection(foot=foot, s_o=s_o, distance=d, signed_distance=side * d, side=side,
                          phi=self._phi(t_best, s_o), kappa_o=self._kappa(t_best))

    def _refine(self, q: NDArray[np.float64], t: NDArray[np.float64], h: float) -> NDArray[np.float64]:
        """Newton's method for the stationary point of |c(t) - q|^2 / 2 near the sample ``t``.

        Steps are limited to two sample spacings ``h`` (a step against a non-positive second
        derivative moves downhill by ``h``); converges quadratically from the nearest sample.
        """
        t = t.copy()
        for _ in range(12):
            c0, c1, c2 = self._c(t, 0), self._c(t, 1), self._c(t, 2)
            rel = c0 - q
            g = np.sum(rel * c1, axis=1)
            dg = np.sum(c1 * c1, axis=1) + np.sum(rel * c2, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(dg > 0.0, -g / dg, -np.sign(g) * h)
            step = np.clip(step, -2.0 * h, 2.0 * h)
            t += step
            if np.max(np.abs(step)) <= 1e-13:  # t in [0, 2 pi): ~1e-14 of the curve's length
                break
        return np.mod(t, TWO_PI)

    def __repr__(self) -> str:
        shown = {k: v for k, v in self.params.items() if k != "points"}
        return f"Boundary(kind={self.kind!r}, length={self.length:.6g}, params={shown})"


# ---------------------------------------------------------------------- constructors
def _finite_positive(name: str, value: float) -> float:
    return real(name, value, lo=0.0, lo_open=True)


def _center(center: ArrayLike) -> NDArray[np.float64]:
    c = float_array("center", center)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise InvalidParameterError(f"center must be two finite numbers (x, y), got {center!r}")
    return c


def _uniform_breakpoints(panels: int = 64) -> NDArray[np.float64]:
    return np.linspace(0.0, TWO_PI, panels + 1)


def ellipse(a: float, b: float, center: ArrayLike = (0.0, 0.0), angle: float = 0.0) -> Boundary:
    """Ellipse with semi-axes ``a`` (along ``angle``) and ``b``, counter-clockwise.

    ``c(t) = center + R(angle) (a cos t, b sin t)``; ``s_o = 0`` at the end of the ``a`` axis.
    """
    a_, b_ = _finite_positive("a", a), _finite_positive("b", b)
    c0 = _center(center)
    ang = real("angle", angle)
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    scale = np.array([a_, b_])

    def curve(t: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        local = _rot(k, t) * scale
        out = local @ rot.T
        return out + c0 if k == 0 else out

    return Boundary(
        curve,
        _uniform_breakpoints(),
        kind="ellipse",
        params={"a": a_, "b": b_, "center": c0.tolist(), "angle": ang},
    )


def circle(R: float, center: ArrayLike = (0.0, 0.0)) -> Boundary:
    """Circle of radius ``R``: curvature 1/R, length 2 pi R; ``s_o = 0`` at center + (R, 0)."""
    r = _finite_positive("R", R)
    b = ellipse(r, r, center)
    b.kind, b.params = "circle", {"R": r, "center": _center(center).tolist()}
    return b


def fourier_polar(
    R: float,
    cos_coeffs: ArrayLike = (),
    sin_coeffs: ArrayLike = (),
    center: ArrayLike = (0.0, 0.0),
) -> Boundary:
    """Star-shaped curve ``c(t) = center + R (1 + sum_k a_k cos kt + b_k sin kt) (cos t, sin t)``.

    ``cos_coeffs[k-1] = a_k``, ``sin_coeffs[k-1] = b_k`` for k = 1, 2, ... The radius factor
    must stay positive (so the curve is simple); otherwise a DegenerateBoundaryError is raised.
    """
    r0 = _finite_positive("R", R)
    a = np.atleast_1d(float_array("cos_coeffs", cos_coeffs))
    b = np.atleast_1d(float_array("sin_coeffs", sin_coeffs))
    if a.ndim != 1 or b.ndim != 1:
        raise InvalidParameterError("Fourier coefficients must be 1-D sequences")
    n = max(a.size, b.size)
    if n > _MAX_HARMONICS:
        raise InvalidParameterError(f"at most {_MAX_HARMONICS} Fourier harmonics are supported, got {n}")
    a = np.pad(a, (0, n - a.size))
    b = np.pad(b, (0, n - b.size))
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise InvalidParameterError("Fourier coefficients must be finite")
    c0 = _center(center)
    kk = np.arange(1, n + 1, dtype=float)

    def radius(t: NDArray[np.float64], j: int) -> NDArray[np.float64]:
        """j-th derivative of the polar radius."""
        if n == 0:
            return np.full_like(t, r0 if j == 0 else 0.0)
        ph = np.outer(t, kk) + j * np.pi / 2.0
        val = (np.cos(ph) * a + np.sin(ph) * b) @ (kk**j)
        return r0 * (val + (1.0 if j == 0 else 0.0))

    tt = np.linspace(0.0, TWO_PI, 8192, endpoint=False)
    if np.min(radius(tt, 0)) <= 1e-9 * r0:
        raise DegenerateBoundaryError(
            "polar radius 1 + sum(a_k cos kt + b_k sin kt) must stay > 0 for a simple curve"
        )

    def curve(t: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        out = sum((comb(k, j) * radius(t, j)[:, None] * _rot(k - j, t) for j in range(k + 1)), np.zeros((t.size, 2)))
        return out + c0 if k == 0 else out

    panels = max(64, 8 * n)
    return Boundary(
        curve,
        _uniform_breakpoints(panels),
        kind="fourier_polar",
        params={"R": r0, "cos_coeffs": a.tolist(), "sin_coeffs": b.tolist(), "center": c0.tolist()},
    )


def deformed_circle(
    R: float = 5.0,
    amplitude: float = 0.15,
    lobes: int = 3,
    phase: float = 0.0,
    center: ArrayLike = (0.0, 0.0),
) -> Boundary:
    """The paper's third object: a circle of radius ``R`` smoothly deformed into lobes.

    ``c(t) = center + R (1 + amplitude cos(lobes (t - phase))) (cos t, sin t)``.
    The curve has concave parts when ``amplitude > 1 / (1 + lobes^2)`` (0.1 for 3 lobes);
    the default (R = 5, amplitude 0.15, 3 lobes) has minimum curvature about -0.138
    (concave radius about 7.2) between the lobes.
    """
    m = integer("lobes", lobes, lo=2, hi=_MAX_HARMONICS)
    amp = real("amplitude", amplitude, lo=0.0, hi=1.0, hi_open=True)
    phase = real("phase", phase)
    R = _finite_positive("R", R)
    cos_c = np.zeros(m)
    sin_c = np.zeros(m)
    cos_c[m - 1] = amp * np.cos(m * phase)
    sin_c[m - 1] = amp * np.sin(m * phase)
    b = fourier_polar(R, cos_c, sin_c, center)
    b.kind = "deformed_circle"
    b.params = {"R": float(R), "amplitude": amp, "lobes": m, "phase": float(phase), "center": list(b.params["center"])}
    return b


# ---------------------------------------------------------------------- user points
def _segments_intersect(p: NDArray[np.float64]) -> bool:
    """True if any two non-adjacent edges of the closed polygon ``p`` (n, 2) intersect."""
    n = len(p)
    a, b = p, np.roll(p, -1, axis=0)

    def orient(o: NDArray, u: NDArray, v: NDArray) -> NDArray:
        return (u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - (u[..., 1] - o[..., 1]) * (v[..., 0] - o[..., 0])

    block = max(1, 4_000_000 // max(n, 1))
    j = np.arange(n)
    for start in range(0, n, block):
        i = np.arange(start, min(n, start + block))[:, None]
        ai, bi = a[i], b[i]
        aj, bj = a[None, :], b[None, :]
        o1, o2 = orient(ai, bi, aj), orient(ai, bi, bj)
        o3, o4 = orient(aj, bj, ai), orient(aj, bj, bi)
        cross = (o1 * o2 < 0) & (o3 * o4 < 0)
        gap = np.abs(i - j[None, :])
        adjacent = (gap <= 1) | (gap == n - 1)
        if np.any(cross & ~adjacent):
            return True
    return False


def from_points(
    points: ArrayLike,
    *,
    closed: bool = False,
    smoothing: float = 0.0,
) -> Boundary:
    """Closed smooth curve through user points (e.g. a CSV outline or an SVG-like polygon).

    A closed periodic quintic spline (C^4, so curvature and its derivative are continuous)
    is fitted through the points, parameterised by cumulative chord length; ``smoothing`` is
    scipy's ``splprep`` smoothing factor relative to the number of points and the squared
    size of the outline (0 interpolates). The polygon must be closed: its last point must
    repeat the first, unless ``closed=True`` says the outline closes back to the first
    point implicitly. Clockwise input is reversed to counter-clockwise.

    Raises NotClosedError (open polyline), SelfIntersectionError (the polygon or the fitted
    curve crosses itself) or DegenerateBoundaryError (fewer than 5 distinct points, zero area,
    non-finite values).
    """
    p = float_array("points", points, error=DegenerateBoundaryError)
    if p.ndim != 2 or p.shape[1] != 2:
        raise DegenerateBoundaryError(f"points must be an (n, 2) array, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise DegenerateBoundaryError("points contain NaN or infinite values")
    if np.any(np.abs(p) > 1e100):
        raise DegenerateBoundaryError("point coordinates must lie within +-1e100 (choose units)")
    smoothing = real("smoothing", smoothing, lo=0.0)
    if len(p) < 5:
        raise DegenerateBoundaryError(f"need at least 5 distinct points, got {len(p)}")
    size = float(np.max(np.ptp(p, axis=0)))
    if size <= 0.0:
        raise DegenerateBoundaryError("all points coincide")
    gap = float(np.hypot(*(p[-1] - p[0])))
    if gap <= 1e-9 * size:
        p = p[:-1]
    elif not closed:
        raise NotClosedError(
            f"the outline is an open polyline: its last point is {gap:.6g} away from its first; "
            "repeat the first point at the end, or pass closed=True (CLI: --closed) to close it"
        )
    keep = np.hypot(*np.diff(p, axis=0, append=p[:1]).T) > 1e-12 * size
    p = p[keep]
    if len(p) < 5:
        raise DegenerateBoundaryError(f"need at least 5 distinct points, got {len(p)}")
    x, y = p[:, 0], p[:, 1]
    area = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    if abs(area) <= 1e-9 * size**2:
        raise DegenerateBoundaryError("the outline encloses zero area")
    if _segments_intersect(p):
        raise SelfIntersectionError("the polygon through the given points crosses itself")
    if area < 0.0:
        p = p[::-1]
    closed_pts = np.vstack([p, p[:1]])
    chord = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed_pts, axis=0).T))])
    u = chord / chord[-1]
    # below 1e-12 the smoothing is at rounding level (and FITPACK warns that it cannot reach it)
    s_fit = smoothing * len(p) * size**2 if smoothing >= 1e-12 else 0.0
    from scipy.interpolate import splev, splprep

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        tck, _ = splprep(closed_pts.T, u=u, per=1, k=5, s=s_fit, quiet=True)
    if s_fit > 0.0 and any(issubclass(w.category, RuntimeWarning) for w in caught):
        # FITPACK cannot reach a smoothing this small ("s too small"): its limit is interpolation
        tck, _ = splprep(closed_pts.T, u=u, per=1, k=5, s=0.0, quiet=True)
    # splprep returns the list [knots, [coefficients of x, of y], degree]; its stub types the
    # items as one union, so name the actual layout for splev
    spline = cast("tuple[NDArray[np.float64], list[NDArray[np.float64]], int]", tuple(tck))

    def curve(t: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        uu = np.mod(t, TWO_PI) / TWO_PI
        vals = np.asarray(splev(uu, spline, der=k))
        return vals.T / TWO_PI**k

    knots = np.unique(np.clip(tck[0], 0.0, 1.0)) * TWO_PI
    sub = np.linspace(0.0, 1.0, 3)[:-1]
    bp = np.concatenate([(knots[:-1, None] + np.diff(knots)[:, None] * sub).ravel(), [TWO_PI]])
    dense = curve(np.linspace(0.0, TWO_PI, 2048, endpoint=False), 0)
    if _segments_intersect(dense):
        raise SelfIntersectionError(
            "the smooth curve fitted through the points crosses itself; add points or smooth more"
        )
    # the points the spline interpolates (distinct, counter-clockwise): from_points(points,
    # closed=True, smoothing=...) rebuilds this very curve (the ROS object message carries them)
    through = np.array(p, dtype=float)
    through.flags.writeable = False
    return Boundary(curve, bp, kind="points", params={"n_points": len(p), "smoothing": smoothing, "points": through})


def load_points(path: str) -> NDArray[np.float64]:
    """Read an outline from a CSV/whitespace text file with two columns x, y (header allowed)."""
    if not isinstance(path, str | os.PathLike):
        raise InvalidParameterError(f"outline file must be a path, got {path!r}")
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as exc:
        raise InvalidParameterError(f"cannot read outline file {path!r}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise DegenerateBoundaryError(f"outline file {path!r} is not a text file: {exc}") from exc
    rows: list[list[float]] = []
    for line_no, line in enumerate(text.splitlines(), start=1):
        fields = [f for f in line.replace(",", " ").split() if f]
        if not fields or line.lstrip().startswith("#"):
            continue
        try:
            row = [float(fields[0]), float(fields[1])]
        except (ValueError, IndexError) as exc:
            if rows:  # a header line before the data is fine; garbage after it is not
                raise DegenerateBoundaryError(f"{path}:{line_no}: expected two numbers x, y, got {line!r}") from exc
            continue
        if len(fields) != 2:
            raise DegenerateBoundaryError(f"{path}:{line_no}: expected two columns x, y, got {len(fields)}: {line!r}")
        if not (np.isfinite(row[0]) and np.isfinite(row[1])):
            raise DegenerateBoundaryError(f"{path}:{line_no}: x, y must be finite numbers, got {line!r}")
        rows.append(row)
    if not rows:
        raise DegenerateBoundaryError(f"{path}: no x, y rows found (two numbers per line, separated by a comma or "
                                      "white space; a header line allowed)")
    return np.asarray(rows)
