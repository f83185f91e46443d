"""The discretised optimal-grasp problem (eq. (9)): dynamics, cost, exact adjoint.

One discretisation shared by every solver: ``N`` nodes on ``[0, L]``, state ``(rho, alpha,
s_o)``, eq. (8) with eq. (7) by the implicit trapezoidal rule, the cost by the trapezoid rule,
the object curvature as a periodic cubic spline (:class:`CurvatureTable`), the state constraints
as an augmented-Lagrangian term. The exact discrete adjoint gives the reduced gradient and the
nodal costates (the discrete counterparts of eq. (12)); ``frozen=True`` drops ``d kappa_o / d
s_o``, the paper's costate equations. docs/optimal.md, "Discretisation" and "Exact discrete gradient".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Literal, overload

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline
from scipy.linalg import lapack

from ..boundary import Boundary
from ..errors import RunFailure

__all__ = [
    "CurvatureTable",
    "Discretisation",
    "Trajectory",
    "Linearisation",
    "PenaltyState",
    "linearise",
    "dynamics",
    "dynamics_jacobian",
    "dynamics_hessian",
    "residual",
    "solve_states",
    "solve_states_linearised",
    "march_states",
    "evaluate",
    "adjoint",
    "nodal_costates",
    "lagrangian_hessian_blocks",
    "kkt_newton_step",
    "kkt_solve",
    "kkt_resolve",
    "KKTFactor",
    "lagrangian_gradient",
    "ForwardSolveError",
    "SingularSystemError",
]

Array = NDArray[np.float64]
IndexArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class CurvatureTable:
    """kappa_o(s_o) as a periodic C^2 cubic spline on ``size`` uniform samples of the boundary.

    ``__call__`` returns ``(kappa_o, dkappa_o/ds_o, d^2kappa_o/ds_o^2)``, mutually consistent
    (each is the exact derivative of the previous), for any real ``s_o`` (taken mod L_o).
    """

    length: float
    coeffs: Array  # (4, size): cubic coefficients of every cell, highest power first
    step: float

    @classmethod
    def from_boundary(cls, boundary: Boundary, size: int = 4096) -> CurvatureTable:
        """Tabulate the boundary's curvature at ``size`` equally spaced arclengths."""
        x = np.linspace(0.0, boundary.length, int(size) + 1)
        k = boundary.curvature(x[:-1])
        spline = CubicSpline(x, np.append(k, k[0]), bc_type="periodic")
        return cls(length=float(boundary.length), coeffs=np.ascontiguousarray(spline.c), step=float(x[1] - x[0]))

    def __call__(self, s_o: Array) -> tuple[Array, Array, Array]:
        s = np.mod(np.asarray(s_o, dtype=float), self.length)
        j = np.minimum((s / self.step).astype(np.int64), self.coeffs.shape[1] - 1)
        t = s - j * self.step
        c0, c1, c2, c3, d0, d1, e0 = self._rows[j].T  # one gather of the cell's coefficients
        k = ((c0 * t + c1) * t + c2) * t + c3
        k1 = (d0 * t + d1) * t + c2
        k2 = e0 * t + d1
        return k, k1, k2

    def scalar(self) -> tuple[list[list[float]], float, float]:
        """(coefficient lists, step, length) for fast pure-Python scalar evaluation."""
        return self._scalar_lists, self.step, self.length

    @cached_property
    def _scalar_lists(self) -> list[list[float]]:
        return self.coeffs.tolist()

    @cached_property
    def _rows(self) -> Array:
        """Per cell: c0..c3 and the derivative coefficients 3 c0, 2 c1, 6 c0, shape (size, 7)."""
        c0, c1, c2, c3 = self.coeffs
        return np.ascontiguousarray(np.stack([c0, c1, c2, c3, 3.0 * c0, 2.0 * c1, 6.0 * c0], axis=-1))


@dataclass(frozen=True, eq=False)
class Discretisation:
    """Everything the discrete problem needs, as plain arrays (no boundary object)."""

    s: Array  # (N,) nodes
    h: float
    w: Array  # (N,) trapezoid weights
    x0: Array  # (3,) initial state (rho0, alpha0, s_o0)
    rho_d: Array  # (N,)
    alpha_d: Array  # (N,)
    chi: float
    table: CurvatureTable
    margins: tuple[float, float, float]  # (rho, alpha, 1 + rho kappa_o) constraint margins

    @property
    def nodes(self) -> int:
        return len(self.s)

    @cached_property
    def kkt_pattern(self) -> tuple[IndexArray, Array, IndexArray, IndexArray]:
        """Index layout of the banded KKT matrix (computed once per discretisation)."""
        return _kkt_pattern(self)

    @cached_property
    def state_band_pattern(self) -> tuple[Array, Array]:
        """Flat band-storage positions of dc/dx and of its transpose (computed once)."""
        return _state_band_pattern(self.nodes, False), _state_band_pattern(self.nodes, True)

    def coarsened(self, nodes: int) -> Discretisation:
        """The same problem on ``nodes`` grid points (profiles interpolated linearly; cached)."""
        cache = self._coarse
        if nodes not in cache:
            s = np.linspace(0.0, float(self.s[-1]), nodes)
            h = float(s[1] - s[0])
            w = np.full(nodes, h)
            w[0] = w[-1] = 0.5 * h
            rho_d, alpha_d = np.interp(s, self.s, self.rho_d), np.interp(s, self.s, self.alpha_d)
            cache[nodes] = replace(self, s=s, h=h, w=w, rho_d=rho_d, alpha_d=alpha_d)
        return cache[nodes]

    @cached_property
    def _coarse(self) -> dict[int, Discretisation]:
        return {}


@dataclass(frozen=True, eq=False)
class PenaltyState:
    """Augmented-Lagrangian data: multipliers ``y`` (N, 4) >= 0 and penalty weight ``mu``.

    ``mu = 0`` (with ``y = 0``) switches the penalty off: the plain cost J.
    """

    y: Array
    mu: float

    @classmethod
    def zero(cls, nodes: int, mu: float) -> PenaltyState:
        return cls(np.zeros((nodes, 4)), float(mu))


@dataclass(frozen=True, eq=False)
class Linearisation:
    """The dynamics at one trajectory (x, u), evaluated once and shared by the defect check of
    the forward solve, the adjoint, the Lagrangian Hessian and the KKT matrix.

    ``k, k1, k2``: kappa_o and its first two derivatives at s_o (:class:`CurvatureTable`);
    ``S, C``: sin, cos alpha; ``D = 1 + rho kappa_o``; ``f`` (n, 3) of eqs. (8) and
    (7); ``A = df/dx`` (n, 3, 3), formed on first use.
    """

    x: Array
    u: Array
    k: Array
    k1: Array
    k2: Array
    S: Array
    C: Array
    D: Array
    f: Array

    @cached_property
    def A(self) -> Array:
        return self.jacobian()

    def jacobian(self, frozen: bool = False) -> Array:
        """df/dx, shape (n, 3, 3); ``frozen`` drops the s_o dependence of kappa_o (eq. (12))."""
        rho, S, C, D, k = self.x[:, 0], self.S, self.C, self.D, self.k
        k1 = np.zeros_like(k) if frozen else self.k1
        SD2 = S / (D * D)
        A = np.zeros((len(rho), 3, 3))
        A[:, 0, 1] = S
        A[:, 1, 0] = -SD2 * k * k
        A[:, 1, 1] = k * C / D
        A[:, 1, 2] = k1 * SD2
        A[:, 2, 0] = -SD2 * k
        A[:, 2, 1] = C / D
        A[:, 2, 2] = -SD2 * rho * k1
        return A


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A control and its consistent states, with the cost split into tracking and penalty.

    ``lin``: the dynamics linearised at (x, u) when the caller already had them (reused by
    :func:`adjoint` and :func:`kkt_newton_step`), else None.
    """

    u: Array  # (N,)
    x: Array  # (N, 3)
    cost: float  # J of eq. (9) (discretised), without the penalty
    penalty: float  # augmented-Lagrangian term
    lin: Linearisation | None = None

    @property
    def total(self) -> float:
        return self.cost + self.penalty


# ----------------------------------------------------------------------------- dynamics
def linearise(x: Array, u: Array, table: CurvatureTable) -> Linearisation:
    """Evaluate f(x, u) of eqs. (8) / (7) and the pieces of its derivatives."""
    rho, alpha, sig = x[:, 0], x[:, 1], x[:, 2]
    k, k1, k2 = table(sig)
    S, C = np.sin(alpha), np.cos(alpha)
    D = 1.0 + rho * k
    g = S / D
    f = np.empty((len(rho), 3))
    f[:, 0] = -C
    f[:, 1] = k * g - u
    f[:, 2] = g
    return Linearisation(x=x, u=u, k=k, k1=k1, k2=k2, S=S, C=C, D=D, f=f)


def dynamics(x: Array, u: Array, table: CurvatureTable) -> Array:
    """f(x, u) of eqs. (8) and (7), vectorised over rows of ``x`` (n, 3)."""
    return linearise(x, u, table).f


def dynamics_jacobian(x: Array, u: Array, table: CurvatureTable, frozen: bool = False) -> tuple[Array, Array]:
    """(f, A = df/dx) with A of shape (n, 3, 3); ``frozen`` drops the s_o dependence of kappa_o."""
    lin = linearise(x, u, table)
    return lin.f, lin.jacobian(frozen)


def _second_derivatives(lin: Linearisation) -> tuple[Array, ...]:
    """The distinct second derivatives of f_1 = kappa_o g - u and f_2 = g = sin(alpha) / D.

    Returns ``(g00, g01, g11, f12, f22, f02, g02)`` with ``g_ab = d^2 g / dx_a dx_b`` and
    ``f_ab = d^2 (kappa_o g) / dx_a dx_b`` (x = (rho, alpha, s_o)); the others follow from
    ``f_ab = kappa_o g_ab`` for ab in {00, 01, 11} and ``g_ab = -rho f_ab`` for ab in {12, 22}.
    """
    rho, S, C, D, k, k1, k2 = lin.x[:, 0], lin.S, lin.C, lin.D, lin.k, lin.k1, lin.k2
    SD3 = S / (D * D * D)
    CD2 = C / (D * D)
    return (
        2.0 * k * k * SD3,
        -k * CD2,
        -S / D,
        k1 * CD2,
        (k2 * D - 2.0 * rho * k1 * k1) * SD3,
        -2.0 * k * k1 * SD3,
        -k1 * (1.0 - rho * k) * SD3,
    )


def dynamics_hessian(x: Array, table: CurvatureTable) -> Array:
    """Second derivatives d^2 f_m / dx_a dx_b, shape (n, 3, 3, 3) indexed [node, m, a, b]."""
    lin = linearise(x, np.zeros(len(x)), table)
    rho, k = x[:, 0], lin.k
    g00, g01, g11, f12, f22, f02, g02 = _second_derivatives(lin)
    F = {(0, 0): k * g00, (0, 1): k * g01, (0, 2): f02, (1, 1): k * g11, (1, 2): f12, (2, 2): f22}
    G = {(0, 0): g00, (0, 1): g01, (0, 2): g02, (1, 1): g11, (1, 2): -rho * f12, (2, 2): -rho * f22}
    Hs = np.zeros((len(x), 3, 3, 3))
    Hs[:, 0, 1, 1] = lin.C
    for (a, b), v in F.items():
        Hs[:, 1, a, b] = Hs[:, 1, b, a] = v
        Hs[:, 2, a, b] = Hs[:, 2, b, a] = G[(a, b)]
    return Hs


def residual(d: Discretisation, x: Array, u: Array) -> Array:
    """Trapezoidal defects c_i, shape (N-1, 3)."""
    f = dynamics(x, u, d.table)
    return x[1:] - x[:-1] - 0.5 * d.h * (f[1:] + f[:-1])


# ----------------------------------------------------------------------------- banded linear algebra
_GBSV, _GBTRF, _GBTRS = lapack.dgbsv, lapack.dgbtrf, lapack.dgbtrs  # the float64 banded routines


class SingularSystemError(RunFailure):
    """A banded linear system of the discrete problem is singular."""


def _band_solve(ab: Array, kl: int, ku: int, rhs: Array) -> Array:
    """Solve with LAPACK gbsv; ``ab`` (Fortran order, so no copy) has ``2 kl + ku + 1`` rows,
    entry (r, c) at ``[kl + ku + r - c, c]``."""
    _, _, x, info = _GBSV(kl, ku, ab, rhs, overwrite_ab=True, overwrite_b=True)
    if info != 0:
        raise SingularSystemError(f"banded solve failed (LAPACK gbsv info = {info})")
    return x


def _band_matrix(buf: Array, rows: int) -> Array:
    """View a flat buffer filled at ``(kl + ku + r - c) + rows c`` as the Fortran-ordered band."""
    return buf.reshape(-1, rows).T


def _step_blocks(d: Discretisation, A: Array) -> Array:
    """The 3x3 blocks of dc/dx: ``I - h/2 A_{i+1}`` (c_i w.r.t. x_{i+1}, i = 0..N-2), then
    ``-(I + h/2 A_i)`` (c_i w.r.t. x_i, i = 1..N-2); shape (2N - 3, 3, 3)."""
    n1 = d.nodes - 1
    h2 = 0.5 * d.h
    blocks = np.empty((2 * n1 - 1, 3, 3))
    np.multiply(A[1:], -h2, out=blocks[:n1])
    np.multiply(A[1:-1], -h2, out=blocks[n1:])
    diag = blocks.reshape(-1, 9)[:, ::4]
    diag[:n1] += 1.0
    diag[n1:] -= 1.0
    return blocks


def _state_band_pattern(n: int, transpose: bool) -> Array:
    """Flat positions (see :func:`_band_matrix`) of the :func:`_step_blocks` entries in dc/dx
    (kl, ku = 5, 2: 13 band rows) or in its transpose (kl, ku = 2, 5: 10 band rows)."""
    n1 = n - 1
    i = np.arange(n1)[:, None, None]
    a = np.arange(3)[None, :, None]
    b = np.arange(3)[None, None, :]
    zero = 0 * i + 0 * a + 0 * b
    r = np.concatenate([(3 * i + a + zero).ravel(), (3 * i[1:] + a + zero[1:]).ravel()])
    c = np.concatenate([(3 * i + b + zero).ravel(), (3 * i[1:] - 3 + b + zero[1:]).ravel()])
    if transpose:
        return (7 + c - r) + 10 * r
    return (7 + r - c) + 13 * c


def _state_jacobian_band(d: Discretisation, A: Array, transpose: bool) -> tuple[Array, int, int]:
    """dc/d(x_1..x_{N-1}) (or its transpose) in gbsv band storage: (ab, kl, ku).

    Block lower-bidiagonal: block (i, i) = I - h/2 A_{i+1} (c_i w.r.t. x_{i+1}),
    block (i, i-1) = -(I + h/2 A_i) (c_i w.r.t. x_i). One vectorised scatter into a
    precomputed layout (:attr:`Discretisation.state_band_pattern`).
    """
    pattern = d.state_band_pattern[1 if transpose else 0]
    kl, ku = (2, 5) if transpose else (5, 2)
    rows = 2 * kl + ku + 1
    buf = np.zeros(rows * 3 * (d.nodes - 1))
    buf[pattern] = _step_blocks(d, A).ravel()
    return _band_matrix(buf, rows), kl, ku


class ForwardSolveError(RunFailure):
    """The implicit trapezoidal steps could not be solved (state left the domain of f)."""


def solve_states(
    d: Discretisation, u: Array, guess: Array | None = None, *, tol: float = 1e-13, max_newton: int = 12
) -> Array:
    """States x (N, 3) with c(x, u) = 0 (the forward integration of eq. (8)).

    Newton's method on the whole block-bidiagonal trapezoidal system, started from ``guess``
    (e.g. the previous iterate; one increase of the defects in a row is tolerated, as happens in
    the first step from a cold guess); if that fails, the steps are solved one after another
    (:func:`march_states`). Raises ForwardSolveError if the dynamics become singular
    (1 + rho kappa_o <= 0).
    """
    return solve_states_linearised(d, u, guess, tol=tol, max_newton=max_newton)[0]


def solve_states_linearised(
    d: Discretisation,
    u: Array,
    guess: Array | None = None,
    *,
    tol: float = 1e-13,
    max_newton: int = 12,
    march: bool = True,
    chord: bool = False,
) -> tuple[Array, Linearisation]:
    """:func:`solve_states` and the dynamics linearised at the returned states.

    The linearisation is the one the last Newton check evaluated (the defects are computed from
    it), so the adjoint and the KKT matrix at the new iterate need no further evaluation.
    ``march=False``: raise ForwardSolveError instead of falling back to :func:`march_states`
    when Newton from ``guess`` fails (a line search then simply shortens its step).
    ``chord=True``: once an iteration has reduced the defects 1000-fold (the Jacobian then
    changes by about the size of the remaining correction), later iterations reuse its LU
    factors (LAPACK gbtrs) instead of forming and factorising a new Jacobian.
    """
    if guess is not None and guess.shape == (d.nodes, 3):
        x = guess.copy()
        x[0] = d.x0
        scale = 1.0 + np.max(np.abs(x), axis=0)
        prev = np.inf
        rises = 0
        factor = None
        for _ in range(max_newton):
            if not np.all(np.isfinite(x)):
                break
            lin = linearise(x, u, d.table)
            if np.any(lin.D <= 0.0):
                break
            f = lin.f
            c = x[1:] - x[:-1] - 0.5 * d.h * (f[1:] + f[:-1])
            err = float(np.max(np.abs(c) / scale))
            if err <= tol:
                return x, lin
            rises = 0 if err < prev else rises + 1
            if not np.isfinite(err) or rises > 1:
                break
            contracted = err <= 1e-3 * prev
            prev = err
            if factor is not None and contracted:
                dx, info = _GBTRS(factor[0], 5, 2, -c.ravel(), factor[1], overwrite_b=True)
                if info != 0:
                    break
            else:
                ab, kl, ku = _state_jacobian_band(d, lin.A, transpose=False)
                if chord:
                    lu, piv, info = _GBTRF(ab, kl, ku, overwrite_ab=True)
                    if info != 0:
                        break
                    factor = (lu, piv)
                    dx, info = _GBTRS(lu, kl, ku, -c.ravel(), piv, overwrite_b=True)
                    if info != 0:
                        break
                else:
                    try:
                        dx = _band_solve(ab, kl, ku, -c.ravel())
                    except SingularSystemError:
                        break
            x[1:] += dx.reshape(-1, 3)
    if not march:
        raise ForwardSolveError("Newton on the trapezoidal trajectory did not converge from the guess")
    x = march_states(d, u)
    return x, linearise(x, u, d.table)


def march_states(d: Discretisation, u: Array) -> Array:
    """Solve the implicit trapezoidal steps sequentially (pure-Python 3x3 Newton per step)."""
    coeffs, step, length = d.table.scalar()
    c0, c1, c2, c3 = coeffs
    ncell = len(c0)

    def kap(sig: float) -> tuple[float, float]:
        sm = sig % length
        j = min(int(sm / step), ncell - 1)
        t = sm - j * step
        return ((c0[j] * t + c1[j]) * t + c2[j]) * t + c3[j], (3.0 * c0[j] * t + 2.0 * c1[j]) * t + c2[j]

    h2 = 0.5 * d.h
    uu = [float(v) for v in u]
    out = np.empty((d.nodes, 3))
    r, a, sg = (float(v) for v in d.x0)
    out[0] = (r, a, sg)
    k, _ = kap(sg)
    D = 1.0 + r * k
    if D <= 0.0:
        raise ForwardSolveError("1 + rho kappa_o <= 0 at the base")
    g = math.sin(a) / D
    f0, f1, f2 = -math.cos(a), -uu[0] + k * g, g
    for i in range(1, d.nodes):
        b0, b1, b2 = r + h2 * f0, a + h2 * f1, sg + h2 * f2  # explicit half
        # predictor: explicit Euler
        R, Al, Sg = r + 2 * h2 * f0, a + 2 * h2 * f1, sg + 2 * h2 * f2
        ui = uu[i]
        for _ in range(20):
            k, k1 = kap(Sg)
            S, C = math.sin(Al), math.cos(Al)
            D = 1.0 + R * k
            if not D > 0.0:
                raise ForwardSolveError(f"1 + rho kappa_o <= 0 at node {i}")
            g = S / D
            F0, F1, F2 = -C, -ui + k * g, g
            e0, e1, e2 = R - h2 * F0 - b0, Al - h2 * F1 - b1, Sg - h2 * F2 - b2
            if abs(e0) + abs(e1) + abs(e2) <= 1e-14 * (1.0 + abs(R) + abs(Al) + abs(Sg)):
                break
            D2 = D * D
            a01 = S
            a10, a11, a12 = -S * k * k / D2, k * C / D, k1 * S / D2
            a20, a21, a22 = -S * k / D2, C / D, -S * R * k1 / D2
            # M = I - h2 A ; solve M d = -e by Cramer's rule
            m00, m01, m02 = 1.0, -h2 * a01, 0.0
            m10, m11, m12 = -h2 * a10, 1.0 - h2 * a11, -h2 * a12
            m20, m21, m22 = -h2 * a20, -h2 * a21, 1.0 - h2 * a22
            det = (
                m00 * (m11 * m22 - m12 * m21)
                - m01 * (m10 * m22 - m12 * m20)
                + m02 * (m10 * m21 - m11 * m20)
            )
            r0, r1, r2 = -e0, -e1, -e2
            d0 = (r0 * (m11 * m22 - m12 * m21) - m01 * (r1 * m22 - m12 * r2) + m02 * (r1 * m21 - m11 * r2)) / det
            d1 = (m00 * (r1 * m22 - m12 * r2) - r0 * (m10 * m22 - m12 * m20) + m02 * (m10 * r2 - r1 * m20)) / det
            d2 = (m00 * (m11 * r2 - r1 * m21) - m01 * (m10 * r2 - r1 * m20) + r0 * (m10 * m21 - m11 * m20)) / det
            R, Al, Sg = R + d0, Al + d1, Sg + d2
        else:
            raise ForwardSolveError(f"trapezoidal step {i} did not converge")
        if not (math.isfinite(R) and math.isfinite(Al) and math.isfinite(Sg)):
            raise ForwardSolveError(f"non-finite state at node {i}")
        k, _ = kap(Sg)
        D = 1.0 + R * k
        if not D > 0.0:
            raise ForwardSolveError(f"1 + rho kappa_o <= 0 at node {i}")
        g = math.sin(Al) / D
        f0, f1, f2 = -math.cos(Al), -ui + k * g, g
        r, a, sg = R, Al, Sg
        out[i] = (r, a, sg)
    return out


# ----------------------------------------------------------------------------- cost, penalty
def _constraints(d: Discretisation, x: Array, lin: Linearisation | None = None) -> Array:
    """q (N, 4) >= 0 wanted: rho - m, alpha - m, pi - m - alpha, 1 + rho kappa_o - m.

    kappa_o comes from ``lin`` (the linearisation at ``x``) when given, else from the table.
    """
    rho, alpha = x[:, 0], x[:, 1]
    k = lin.k if lin is not None else d.table(x[:, 2])[0]
    m_rho, m_alpha, m_speed = d.margins
    q = np.empty((len(rho), 4))
    q[:, 0] = rho - m_rho
    q[:, 1] = alpha - m_alpha
    q[:, 2] = (np.pi - m_alpha) - alpha
    q[:, 3] = 1.0 - m_speed + rho * k
    return q


def _constraint_jacobian(
    d: Discretisation, x: Array, lin: Linearisation | None
) -> tuple[Array, Array, Array]:
    """dq/dx (N, 4, 3) and (dkappa_o, d^2kappa_o) at the nodes (only needed when a constraint is active)."""
    rho = x[:, 0]
    k, k1, k2 = (lin.k, lin.k1, lin.k2) if lin is not None else d.table(x[:, 2])
    dq = np.zeros((len(rho), 4, 3))
    dq[:, 0, 0] = 1.0
    dq[:, 1, 1] = 1.0
    dq[:, 2, 1] = -1.0
    dq[:, 3, 0] = k
    dq[:, 3, 2] = rho * k1
    return dq, k1, k2


def evaluate(
    d: Discretisation, u: Array, x: Array, pen: PenaltyState, lin: Linearisation | None = None
) -> Trajectory:
    """Discrete cost (trapezoid rule of eq. (9)'s integrand) and penalty.

    ``lin``: the dynamics linearised at (x, u) if known; kept in the returned trajectory.
    """
    rho, alpha = x[:, 0], x[:, 1]
    run = 0.5 * u * u + d.chi * (0.5 * (rho - d.rho_d) ** 2 + 1.0 - np.cos(alpha - d.alpha_d))
    if pen.mu == 0.0:
        return Trajectory(u=u, x=x, cost=float(d.w @ run), penalty=0.0, lin=lin)
    q = _constraints(d, x, lin)
    act = np.maximum(0.0, pen.y - pen.mu * q)
    psi = (act * act - pen.y * pen.y) / (2.0 * pen.mu)
    return Trajectory(u=u, x=x, cost=float(d.w @ run), penalty=float(d.w @ psi.sum(axis=1)), lin=lin)


def state_gradient(
    d: Discretisation, x: Array, pen: PenaltyState, frozen: bool = False, lin: Linearisation | None = None
) -> Array:
    """d(cost + penalty)/dx_i without the weights' sum over steps, shape (N, 3)."""
    rho, alpha = x[:, 0], x[:, 1]
    gx = np.zeros_like(x)
    gx[:, 0] = d.chi * (rho - d.rho_d)
    gx[:, 1] = d.chi * np.sin(alpha - d.alpha_d)
    act = np.maximum(0.0, pen.y - pen.mu * _constraints(d, x, lin))
    if np.any(act > 0.0):
        dq, _, _ = _constraint_jacobian(d, x, lin)
        if frozen:
            dq[:, 3, 2] = 0.0
        gx -= np.einsum("nj,nja->na", act, dq)
    return d.w[:, None] * gx


def adjoint(d: Discretisation, traj: Trajectory, pen: PenaltyState, frozen: bool = False) -> tuple[Array, Array]:
    """Exact discrete adjoint: multipliers lambda (N-1, 3) and the reduced gradient dJ/du (N,).

    Solves ``(dc/dx)^T lambda = -d(J + P)/dx`` (block upper-bidiagonal, one banded solve).
    With ``frozen`` the kappa_o(s_o) dependence is dropped (paper's costates, eq. (12)).
    Uses ``traj.lin`` when present.
    """
    lin = traj.lin if traj.lin is not None else linearise(traj.x, traj.u, d.table)
    A = lin.jacobian(frozen=True) if frozen else lin.A
    gx = state_gradient(d, traj.x, pen, frozen=frozen, lin=lin)
    ab, kl, ku = _state_jacobian_band(d, A, transpose=True)
    lam = _band_solve(ab, kl, ku, -gx[1:].ravel()).reshape(-1, 3)
    grad = d.w * traj.u
    grad[:-1] += 0.5 * d.h * lam[:, 1]
    grad[1:] += 0.5 * d.h * lam[:, 1]
    return lam, grad


def nodal_costates(d: Discretisation, lam: Array) -> Array:
    """p_j = h / (2 w_j) (lambda_{j-1} + lambda_j), shape (N, 3): kappa_j + p_{j,2} = grad_j / w_j."""
    p = np.zeros((d.nodes, 3))
    p[:-1] += lam
    p[1:] += lam
    return p * (0.5 * d.h / d.w)[:, None]


def lagrangian_hessian_blocks(
    d: Discretisation,
    x: Array,
    lam: Array,
    pen: PenaltyState,
    gauss_newton: bool,
    lin: Linearisation | None = None,
) -> Array:
    """Per-node 3x3 state blocks of the Hessian of the Lagrangian, shape (N, 3, 3).

    Exact: ``w_i (chi diag(1, cos(alpha - alpha_d), 0) + penalty'') - w_i p_i . d^2 f``.
    Gauss-Newton: drops the costate curvature terms and clips ``cos`` at 0 (positive semidefinite).
    ``lin``: the linearisation at ``x`` if known.
    """
    n = d.nodes
    lin = lin if lin is not None else linearise(x, np.zeros(n), d.table)
    H = np.zeros((n, 3, 3))
    cosd = np.cos(x[:, 1] - d.alpha_d)
    H[:, 0, 0] = d.chi
    H[:, 1, 1] = d.chi * (np.maximum(cosd, 0.0) if gauss_newton else cosd)
    act = np.maximum(0.0, pen.y - pen.mu * _constraints(d, x, lin))
    if np.any(act > 0.0):
        dq, k1, k2 = _constraint_jacobian(d, x, lin)
        on = (act > 0.0).astype(float)
        H += pen.mu * np.einsum("nj,nja,njb->nab", on, dq, dq)
        if not gauss_newton:
            # - act * d^2 q4 : q4 = 1 + rho k(sigma) - m
            H[:, 0, 2] -= act[:, 3] * k1
            H[:, 2, 0] -= act[:, 3] * k1
            H[:, 2, 2] -= act[:, 3] * x[:, 0] * k2
    H *= d.w[:, None, None]
    if not gauss_newton:  # - w p . d^2 f, grouped by the relations of _second_derivatives
        p = nodal_costates(d, lam) * d.w[:, None]
        p0, p1, p2 = p[:, 0], p[:, 1], p[:, 2]
        g00, g01, g11, f12, f22, f02, g02 = _second_derivatives(lin)
        a = p1 * lin.k + p2
        b = p1 - x[:, 0] * p2
        H[:, 0, 0] -= a * g00
        H[:, 1, 1] -= a * g11 + p0 * lin.C
        H[:, 2, 2] -= b * f22
        for (i, j), v in (((0, 1), a * g01), ((1, 2), b * f12), ((0, 2), p1 * f02 + p2 * g02)):
            H[:, i, j] -= v
            H[:, j, i] -= v
    return H


def _kkt_pattern(d: Discretisation) -> tuple[IndexArray, Array, IndexArray, IndexArray]:
    """Layout of the banded KKT matrix with the controls eliminated (19 band rows, see
    :func:`kkt_solve`).

    Returns (flat positions of the per-iteration entries - the Hessian blocks H_1..H_{N-1},
    then the :func:`_step_blocks` below and right of the diagonal -, a flat band buffer holding
    the constant entries (the Schur complement of the control block diag(w) on the lambda_2
    unknowns), ix, il) where ``ix`` (N, 3) and ``il`` (N-1, 3) are the unknowns' positions
    (ix[0] = -1: x_0 is fixed).
    """
    n = d.nodes
    size = 6 * n - 6
    ix = np.full((n, 3), -1, dtype=np.int64)
    il = np.empty((n - 1, 3), dtype=np.int64)
    il[0] = [0, 1, 2]
    base = 3 + 6 * np.arange(n - 1)
    ix[1:] = base[:, None] + np.arange(3)
    il[1:] = base[:-1, None] + 3 + np.arange(3)
    a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    i = np.arange(n - 1)
    i1 = i[1:]
    # constraint rows (lambda_i, a) against state columns (x_{i+1}, b) and (x_i, b), i >= 1
    lr = np.concatenate([il[i][:, a].ravel(), il[i1][:, a].ravel()])
    xc = np.concatenate([ix[i + 1][:, b].ravel(), ix[i1][:, b].ravel()])
    rows = np.concatenate([ix[1:, a].ravel(), lr, xc])
    cols = np.concatenate([ix[1:, b].ravel(), xc, lr])

    def flat(r: IndexArray, c: IndexArray) -> IndexArray:
        return (12 + r - c) + 19 * c

    # c_i depends on u_i and u_{i+1} through -h/2 df/du = (0, h/2, 0); eliminating
    # du_j = (r_u,j - h/2 (dlambda_{j-1,2} + dlambda_{j,2})) / w_j leaves -h^2/4 (1/w_i + 1/w_{i+1})
    # on the lambda_{i,2} diagonal and -h^2 / (4 w_{i+1}) between lambda_{i,2} and lambda_{i+1,2}
    q = 0.25 * d.h * d.h / d.w
    template = np.zeros(19 * size)
    template[flat(il[:, 1], il[:, 1])] = -(q[:-1] + q[1:])
    template[flat(il[:-1, 1], il[1:, 1])] = -q[1:-1]
    template[flat(il[1:, 1], il[:-1, 1])] = -q[1:-1]
    return flat(rows, cols), template, ix, il


@dataclass(frozen=True, eq=False)
class KKTFactor:
    """The banded LU factors (LAPACK gbtrf) of one KKT matrix, for further right-hand sides
    (:func:`kkt_resolve`; a triangular solve costs about a third of a factorisation)."""

    lu: Array
    piv: Array


@overload
def kkt_solve(
    d: Discretisation, lin: Linearisation, H: Array, r_u: Array, r_x: Array, r_c: Array,
    *, keep_factor: Literal[False] = False,
) -> tuple[Array, Array, Array]: ...


@overload
def kkt_solve(
    d: Discretisation, lin: Linearisation, H: Array, r_u: Array, r_x: Array, r_c: Array,
    *, keep_factor: Literal[True],
) -> tuple[Array, Array, Array, KKTFactor]: ...


def kkt_solve(
    d: Discretisation,
    lin: Linearisation,
    H: Array,
    r_u: Array,
    r_x: Array,
    r_c: Array,
    *,
    keep_factor: bool = False,
) -> tuple[Array, Array, Array] | tuple[Array, Array, Array, KKTFactor]:
    """Solve the KKT system ``[[H, C^T], [C, 0]] (dx, du, dlambda) = (r_x, r_u, r_c)``.

    ``H``: the per-node state blocks of the Lagrangian Hessian (the control block is diag(w));
    ``C = dc/d(x, u)`` from ``lin``; ``r_u`` (N,), ``r_x`` (N, 3) (row 0 unused: x_0 is
    fixed), ``r_c`` (N-1, 3). The control block diag(w) is eliminated first (Schur
    complement on the lambda_2 unknowns: 6N - 6 unknowns instead of 7N - 6); the ordering
    ``[lam_0, (x_j, lam_j)_{j=1..N-2}, x_{N-1}]`` keeps the symmetric indefinite matrix banded
    (half-bandwidth 6); it is one vectorised scatter into a precomputed layout
    (:attr:`Discretisation.kkt_pattern`) and one LAPACK banded LU (gbsv, partial pivoting). Returns (du (N,), dx (N, 3) with dx_0 = 0, dlambda (N-1, 3)), and with
    ``keep_factor`` also the :class:`KKTFactor` (gbtrf + gbtrs instead of gbsv).
    """
    flat, template, _, _ = d.kkt_pattern
    blocks = _step_blocks(d, lin.A).ravel()
    buf = template.copy()
    buf[flat] = np.concatenate([H[1:].ravel(), blocks, blocks])
    ab = _band_matrix(buf, 19)
    if not keep_factor:
        return _kkt_unpack(d, _band_solve(ab, 6, 6, _kkt_rhs(d, r_u, r_x, r_c)), r_u)
    lu, piv, info = _GBTRF(ab, 6, 6, overwrite_ab=True)
    if info != 0:
        raise SingularSystemError(f"banded factorisation failed (LAPACK gbtrf info = {info})")
    factor = KKTFactor(lu, piv)
    return (*kkt_resolve(d, factor, r_u, r_x, r_c), factor)


def kkt_resolve(
    d: Discretisation, factor: KKTFactor, r_u: Array, r_x: Array, r_c: Array
) -> tuple[Array, Array, Array]:
    """:func:`kkt_solve` with a new right-hand side and the factors of an earlier matrix."""
    sol, info = _GBTRS(factor.lu, 6, 6, _kkt_rhs(d, r_u, r_x, r_c), factor.piv, overwrite_b=True)
    if info != 0:
        raise SingularSystemError(f"banded solve failed (LAPACK gbtrs info = {info})")
    return _kkt_unpack(d, sol, r_u)


def _kkt_rhs(d: Discretisation, r_u: Array, r_x: Array, r_c: Array) -> Array:
    """Right-hand side of the reduced (control-eliminated) KKT system."""
    _, _, ix, il = d.kkt_pattern
    rhs = np.empty(6 * d.nodes - 6)
    rhs[ix[1:]] = r_x[1:]
    rhs[il] = r_c
    ru_w = r_u / d.w
    rhs[il[:, 1]] -= 0.5 * d.h * (ru_w[:-1] + ru_w[1:])
    return rhs


def _kkt_unpack(d: Discretisation, sol: Array, r_u: Array) -> tuple[Array, Array, Array]:
    """(du, dx, dlambda) from the reduced solution (du recovered from the eliminated rows)."""
    _, _, ix, il = d.kkt_pattern
    dx = np.zeros((d.nodes, 3))
    dx[1:] = sol[ix[1:]]
    dlam = sol[il]
    s = r_u.copy()
    s[:-1] -= 0.5 * d.h * dlam[:, 1]
    s[1:] -= 0.5 * d.h * dlam[:, 1]
    return s / d.w, dx, dlam


def kkt_newton_step(
    d: Discretisation, traj: Trajectory, lam: Array, grad: Array, H: Array
) -> tuple[Array, Array]:
    """Newton step (du, dx) of the reduced problem from the sparse KKT system (:func:`kkt_solve`).

    The state is feasible (c = 0) and lambda is the adjoint, so the right-hand side is
    ``-[0, dJ/du, 0]``. The dynamics come from ``traj.lin`` when present.
    """
    n = d.nodes
    lin = traj.lin if traj.lin is not None else linearise(traj.x, traj.u, d.table)
    du, dx, _ = kkt_solve(d, lin, H, -grad, np.zeros((n, 3)), np.zeros((n - 1, 3)))
    return du, dx


def lagrangian_gradient(
    d: Discretisation, lin: Linearisation, lam: Array, pen: PenaltyState
) -> tuple[Array, Array, Array]:
    """(dL/du (N,), dL/dx (N, 3), defects c (N-1, 3)) of ``L = J + P + lambda . c`` at any
    (x, u) = (lin.x, lin.u), feasible or not. At a feasible point with the adjoint lambda,
    dL/dx = 0 (rows 1..N-1) and dL/du is the reduced gradient of :func:`adjoint`.
    """
    x, u, A = lin.x, lin.u, lin.A
    h2 = 0.5 * d.h
    c = x[1:] - x[:-1] - h2 * (lin.f[1:] + lin.f[:-1])
    Lx = state_gradient(d, x, pen, lin=lin)
    Lx[1:] += lam - h2 * np.einsum("nab,na->nb", A[1:], lam)  # (I - h/2 A_{i+1})^T lambda_i
    Lx[1:-1] -= lam[1:] + h2 * np.einsum("nab,na->nb", A[1:-1], lam[1:])  # -(I + h/2 A_i)^T lambda_i
    Lu = d.w * u
    Lu[:-1] += h2 * lam[:, 1]
    Lu[1:] += h2 * lam[:, 1]
    return Lu, Lx, c
