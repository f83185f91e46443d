"""The discretised optimal-grasp problem (eq. optimal_kappa): dynamics, cost, exact adjoint.

Discretisation (shared by every solver, so "the same discretised problem" is literal):

* ``N`` equally spaced nodes ``s_i = i h`` on ``[0, L]``; control ``u_i = kappa(s_i)``;
  state ``x_i = (rho_i, alpha_i, sigma_i)`` with ``sigma = s_o`` the shadow-point arclength.
* Dynamics: eq. rho_alpha_2 with ``s_o' = nu_o`` (eq. object_speed), discretised by the
  implicit trapezoidal rule ``c_i = x_{i+1} - x_i - h/2 (f(x_i, u_i) + f(x_{i+1}, u_{i+1})) = 0``
  with ``x_0 = (rho0, alpha0, s_o0)`` given (second order).
* Cost: trapezoid rule ``J = sum_i w_i l(x_i, u_i)``, ``l = u^2/2 + chi (1/2 (rho - rho_d)^2
  + 1 - cos(alpha - alpha_d))``, ``w = h (1/2, 1, ..., 1, 1/2)``.
* Object curvature: ``kappa_o(sigma)`` is a periodic cubic spline through ``M`` samples of the
  boundary's exact curvature (:class:`CurvatureTable`); its first and second derivatives are
  the spline's own, so the discrete problem is defined with this function and every gradient
  below is exact for it (the table differs from the true curvature by O(M^-4)).
* State constraints (rho > 0, 0 < alpha < pi, 1 + rho kappa_o > 0) enter as a
  Powell-Hestenes-Rockafellar augmented-Lagrangian term (the paper's footnote to the
  Hamiltonian) ``sum_i w_i sum_j psi(q_ij)``, ``psi(q) = (max(0, y - mu q)^2 - y^2) / (2 mu)``.

The adjoint ``lambda_i`` (one 3-vector per step ``c_i``) solves ``(dc/dx)^T lambda = -dJ/dx``;
the reduced gradient is ``dJ/du_j = w_j u_j + h/2 (lambda_{j-1,2} + lambda_{j,2})``. The nodal
costates ``p_j = h / (2 w_j) (lambda_{j-1} + lambda_j)`` are the discrete counterparts of
eq. costates (plus the third costate of s_o), so the gradient reads ``w_j (kappa_j + p_{j,2})``
and the discrete PMP condition is exactly ``kappa_j = -p_{j,2}``.

With ``frozen=True`` the derivative of kappa_o(s_o(s)) with respect to the state is dropped:
that is the gradient of the paper's eq. costates, which are written for a given kappa_o(s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline
from scipy.linalg import get_lapack_funcs

from ..boundary import Boundary

__all__ = [
    "CurvatureTable",
    "Discretisation",
    "Trajectory",
    "PenaltyState",
    "dynamics",
    "dynamics_jacobian",
    "dynamics_hessian",
    "residual",
    "solve_states",
    "march_states",
    "evaluate",
    "adjoint",
    "nodal_costates",
    "lagrangian_hessian_blocks",
    "kkt_newton_step",
    "ForwardSolveError",
    "SingularSystemError",
]

Array = NDArray[np.float64]


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
        c0, c1, c2, c3 = (self.coeffs[m, j] for m in range(4))
        k = ((c0 * t + c1) * t + c2) * t + c3
        k1 = (3.0 * c0 * t + 2.0 * c1) * t + c2
        k2 = 6.0 * c0 * t + 2.0 * c1
        return k, k1, k2

    def scalar(self) -> tuple[list[list[float]], float, float]:
        """(coefficient lists, step, length) for fast pure-Python scalar evaluation."""
        return self._scalar_lists, self.step, self.length

    @cached_property
    def _scalar_lists(self) -> list[list[float]]:
        return self.coeffs.tolist()


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
    def kkt_pattern(self) -> tuple[Array, Array, Array, Array, Array, int]:
        """Index layout of the banded KKT matrix (computed once per discretisation)."""
        return _kkt_pattern(self.nodes)


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
class Trajectory:
    """A control and its consistent states, with the cost split into tracking and penalty."""

    u: Array  # (N,)
    x: Array  # (N, 3)
    cost: float  # J of eq. optimal_kappa (discretised), without the penalty
    penalty: float  # augmented-Lagrangian term

    @property
    def total(self) -> float:
        return self.cost + self.penalty


# ----------------------------------------------------------------------------- dynamics
def dynamics(x: Array, u: Array, table: CurvatureTable) -> Array:
    """f(x, u) of eqs. rho_alpha_2 and object_speed, vectorised over rows of ``x`` (n, 3)."""
    rho, alpha, sig = x[:, 0], x[:, 1], x[:, 2]
    k, _, _ = table(sig)
    g = np.sin(alpha) / (1.0 + rho * k)
    return np.stack([-np.cos(alpha), -u + k * g, g], axis=-1)


def dynamics_jacobian(x: Array, u: Array, table: CurvatureTable, frozen: bool = False) -> tuple[Array, Array]:
    """(f, A = df/dx) with A of shape (n, 3, 3); ``frozen`` drops the s_o dependence of kappa_o."""
    rho, alpha, sig = x[:, 0], x[:, 1], x[:, 2]
    k, k1, _ = table(sig)
    if frozen:
        k1 = np.zeros_like(k1)
    S, C = np.sin(alpha), np.cos(alpha)
    D = 1.0 + rho * k
    g = S / D
    f = np.stack([-C, -u + k * g, g], axis=-1)
    A = np.zeros((len(rho), 3, 3))
    A[:, 0, 1] = S
    A[:, 1, 0] = -S * k * k / D**2
    A[:, 1, 1] = k * C / D
    A[:, 1, 2] = k1 * S / D**2
    A[:, 2, 0] = -S * k / D**2
    A[:, 2, 1] = C / D
    A[:, 2, 2] = -S * rho * k1 / D**2
    return f, A


def dynamics_hessian(x: Array, table: CurvatureTable) -> Array:
    """Second derivatives d^2 f_m / dx_a dx_b, shape (n, 3, 3, 3) indexed [node, m, a, b]."""
    rho, alpha, sig = x[:, 0], x[:, 1], x[:, 2]
    k, k1, k2 = table(sig)
    S, C = np.sin(alpha), np.cos(alpha)
    D = 1.0 + rho * k
    D2, D3 = D**2, D**3
    Hs = np.zeros((len(rho), 3, 3, 3))
    Hs[:, 0, 1, 1] = C
    # m = 1: kappa_o * g
    F = Hs[:, 1]
    F[:, 0, 0] = 2.0 * S * k**3 / D3
    F[:, 0, 1] = F[:, 1, 0] = -C * k * k / D2
    F[:, 0, 2] = F[:, 2, 0] = -2.0 * S * k * k1 / D3
    F[:, 1, 1] = -k * S / D
    F[:, 1, 2] = F[:, 2, 1] = C * k1 / D2
    F[:, 2, 2] = S * (k2 * D - 2.0 * rho * k1 * k1) / D3
    # m = 2: g = sin(alpha) / (1 + rho kappa_o)
    G = Hs[:, 2]
    G[:, 0, 0] = 2.0 * S * k * k / D3
    G[:, 0, 1] = G[:, 1, 0] = -C * k / D2
    G[:, 0, 2] = G[:, 2, 0] = -S * k1 * (1.0 - rho * k) / D3
    G[:, 1, 1] = -S / D
    G[:, 1, 2] = G[:, 2, 1] = -C * rho * k1 / D2
    G[:, 2, 2] = -S * rho * (k2 * D - 2.0 * rho * k1 * k1) / D3
    return Hs


def residual(d: Discretisation, x: Array, u: Array) -> Array:
    """Trapezoidal defects c_i, shape (N-1, 3)."""
    f = dynamics(x, u, d.table)
    return x[1:] - x[:-1] - 0.5 * d.h * (f[1:] + f[:-1])


# ----------------------------------------------------------------------------- banded linear algebra
_GBSV = get_lapack_funcs(("gbsv",), (np.zeros((1, 1)),))[0]


class SingularSystemError(RuntimeError):
    """A banded linear system of the discrete problem is singular."""


def _band_solve(ab: Array, kl: int, ku: int, rhs: Array) -> Array:
    """Solve with LAPACK gbsv; ``ab`` has ``2 kl + ku + 1`` rows, entry (r, c) at ``[kl + ku + r - c, c]``."""
    _, _, x, info = _GBSV(kl, ku, ab, rhs, overwrite_ab=True, overwrite_b=True)
    if info != 0:
        raise SingularSystemError(f"banded solve failed (LAPACK gbsv info = {info})")
    return x


def _state_jacobian_band(d: Discretisation, A: Array, transpose: bool) -> tuple[Array, int, int]:
    """dc/d(x_1..x_{N-1}) (or its transpose) in gbsv band storage: (ab, kl, ku).

    Block lower-bidiagonal: block (i, i) = I - h/2 A_{i+1} (c_i w.r.t. x_{i+1}),
    block (i, i-1) = -(I + h/2 A_i) (c_i w.r.t. x_i).
    """
    n1 = d.nodes - 1
    eye = np.eye(3)
    diag = eye - 0.5 * d.h * A[1:]
    sub = -(eye + 0.5 * d.h * A[1:-1])
    kl, ku = (2, 5) if transpose else (5, 2)
    ab = np.zeros((2 * kl + ku + 1, 3 * n1))
    off = kl + ku
    for a in range(3):
        for b in range(3):
            if transpose:  # (row 3i+b, col 3i+a) and (row 3(i-1)+b, col 3i+a)
                ab[off + b - a, a::3] = diag[:, a, b]
                ab[off + b - a - 3, a::3][1:] = sub[:, a, b]
            else:  # (row 3i+a, col 3i+b) and (row 3i+a, col 3(i-1)+b)
                ab[off + a - b, b::3] = diag[:, a, b]
                ab[off + a - b + 3, b::3][: n1 - 1] = sub[:, a, b]
    return ab, kl, ku


class ForwardSolveError(RuntimeError):
    """The implicit trapezoidal steps could not be solved (state left the domain of f)."""


def solve_states(
    d: Discretisation, u: Array, guess: Array | None = None, *, tol: float = 1e-13, max_newton: int = 12
) -> Array:
    """States x (N, 3) with c(x, u) = 0 (the forward integration of eq. rho_alpha_2).

    Newton's method on the whole block-bidiagonal trapezoidal system, started from ``guess``
    (e.g. the previous iterate); if that fails, the steps are solved one after another
    (:func:`march_states`). Raises ForwardSolveError if the dynamics become singular
    (1 + rho kappa_o <= 0).
    """
    if guess is not None and guess.shape == (d.nodes, 3):
        x = guess.copy()
        x[0] = d.x0
        scale = 1.0 + np.max(np.abs(x), axis=0)
        prev = np.inf
        for _ in range(max_newton):
            if not np.all(np.isfinite(x)):
                break
            f, A = dynamics_jacobian(x, u, d.table)
            if not np.all(np.isfinite(A)) or np.any(1.0 + x[:, 0] * d.table(x[:, 2])[0] <= 0.0):
                break
            c = x[1:] - x[:-1] - 0.5 * d.h * (f[1:] + f[:-1])
            err = float(np.max(np.abs(c) / scale))
            if err <= tol:
                return x
            if not err < prev:
                break
            prev = err
            ab, kl, ku = _state_jacobian_band(d, A, transpose=False)
            try:
                dx = _band_solve(ab, kl, ku, -c.ravel())
            except SingularSystemError:
                break
            x[1:] += dx.reshape(-1, 3)
    return march_states(d, u)


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
def _constraint_values(d: Discretisation, x: Array) -> tuple[Array, Array, Array, Array]:
    """q (N, 4) >= 0 wanted; gradients dq/dx (N, 4, 3); and (k, k1, k2) at the nodes."""
    rho, alpha, sig = x[:, 0], x[:, 1], x[:, 2]
    k, k1, k2 = d.table(sig)
    m_rho, m_alpha, m_speed = d.margins
    q = np.stack([rho - m_rho, alpha - m_alpha, np.pi - m_alpha - alpha, 1.0 + rho * k - m_speed], axis=-1)
    dq = np.zeros((len(rho), 4, 3))
    dq[:, 0, 0] = 1.0
    dq[:, 1, 1] = 1.0
    dq[:, 2, 1] = -1.0
    dq[:, 3, 0] = k
    dq[:, 3, 2] = rho * k1
    return q, dq, k1, k2


def evaluate(d: Discretisation, u: Array, x: Array, pen: PenaltyState) -> Trajectory:
    """Discrete cost (trapezoid rule of eq. optimal_kappa's integrand) and penalty."""
    rho, alpha = x[:, 0], x[:, 1]
    run = 0.5 * u * u + d.chi * (0.5 * (rho - d.rho_d) ** 2 + 1.0 - np.cos(alpha - d.alpha_d))
    if pen.mu == 0.0:
        return Trajectory(u=u, x=x, cost=float(d.w @ run), penalty=0.0)
    q, _, _, _ = _constraint_values(d, x)
    act = np.maximum(0.0, pen.y - pen.mu * q)
    psi = (act * act - pen.y * pen.y) / (2.0 * pen.mu)
    return Trajectory(u=u, x=x, cost=float(d.w @ run), penalty=float(d.w @ psi.sum(axis=1)))


def state_gradient(d: Discretisation, x: Array, pen: PenaltyState, frozen: bool = False) -> Array:
    """d(cost + penalty)/dx_i without the weights' sum over steps, shape (N, 3)."""
    rho, alpha = x[:, 0], x[:, 1]
    gx = np.zeros_like(x)
    gx[:, 0] = d.chi * (rho - d.rho_d)
    gx[:, 1] = d.chi * np.sin(alpha - d.alpha_d)
    q, dq, _, _ = _constraint_values(d, x)
    if frozen:
        dq[:, 3, 2] = 0.0
    act = np.maximum(0.0, pen.y - pen.mu * q)
    gx -= np.einsum("nj,nja->na", act, dq)
    return d.w[:, None] * gx


def adjoint(d: Discretisation, traj: Trajectory, pen: PenaltyState, frozen: bool = False) -> tuple[Array, Array]:
    """Exact discrete adjoint: multipliers lambda (N-1, 3) and the reduced gradient dJ/du (N,).

    Solves ``(dc/dx)^T lambda = -d(J + P)/dx`` (block upper-bidiagonal, one banded solve).
    With ``frozen`` the kappa_o(s_o) dependence is dropped (paper's eq. costates).
    """
    _, A = dynamics_jacobian(traj.x, traj.u, d.table, frozen=frozen)
    gx = state_gradient(d, traj.x, pen, frozen=frozen)
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
    d: Discretisation, x: Array, lam: Array, pen: PenaltyState, gauss_newton: bool
) -> Array:
    """Per-node 3x3 state blocks of the Hessian of the Lagrangian, shape (N, 3, 3).

    Exact: ``w_i (chi diag(1, cos(alpha - alpha_d), 0) + penalty'') - w_i p_i . d^2 f``.
    Gauss-Newton: drops the costate curvature terms and clips ``cos`` at 0 (positive semidefinite).
    """
    n = d.nodes
    H = np.zeros((n, 3, 3))
    cosd = np.cos(x[:, 1] - d.alpha_d)
    H[:, 0, 0] = d.chi
    H[:, 1, 1] = d.chi * (np.maximum(cosd, 0.0) if gauss_newton else cosd)
    q, dq, k1, k2 = _constraint_values(d, x)
    act = np.maximum(0.0, pen.y - pen.mu * q)
    if np.any(act > 0.0):
        on = (act > 0.0).astype(float)
        H += pen.mu * np.einsum("nj,nja,njb->nab", on, dq, dq)
        if not gauss_newton:
            # - act * d^2 q4 : q4 = 1 + rho k(sigma) - m
            H[:, 0, 2] -= act[:, 3] * k1
            H[:, 2, 0] -= act[:, 3] * k1
            H[:, 2, 2] -= act[:, 3] * x[:, 0] * k2
    H *= d.w[:, None, None]
    if not gauss_newton:
        p = nodal_costates(d, lam) * d.w[:, None]
        Hs = dynamics_hessian(x, d.table)
        H -= p[:, 0, None, None] * Hs[:, 0] + p[:, 1, None, None] * Hs[:, 1] + p[:, 2, None, None] * Hs[:, 2]
    return H


def _kkt_pattern(n: int) -> tuple[Array, Array, Array, Array, Array, int]:
    """Index layout of the KKT matrix: (rows, cols, iu, ix, il, size); see kkt_newton_step."""
    size = 7 * n - 6
    iu = np.empty(n, dtype=np.int64)
    ix = np.full((n, 3), -1, dtype=np.int64)
    il = np.empty((n - 1, 3), dtype=np.int64)
    iu[0] = 0
    il[0] = [1, 2, 3]
    base = 4 + 7 * np.arange(n - 1)
    ix[1:] = base[:, None] + np.arange(3)
    iu[1:] = base + 3
    il[1:] = base[:-1, None] + 4 + np.arange(3)
    a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    i = np.arange(n - 1)
    i1 = i[1:]
    rows = [ix[1:, a].ravel(), iu]
    cols = [ix[1:, b].ravel(), iu]
    for r_, c_ in ((il[i][:, a], ix[i + 1][:, b]), (il[i1][:, a], ix[i1][:, b])):
        rows += [r_.ravel(), c_.ravel()]
        cols += [c_.ravel(), r_.ravel()]
    for uu in (iu[i], iu[i + 1]):
        rows += [il[i, 1], uu]
        cols += [uu, il[i, 1]]
    return np.concatenate(rows), np.concatenate(cols), iu, ix, il, size


def kkt_newton_step(
    d: Discretisation, traj: Trajectory, lam: Array, grad: Array, H: Array
) -> tuple[Array, Array]:
    """Newton step (du, dx) of the reduced problem from the sparse KKT system.

    Unknown ordering ``[u_0, lam_0, (x_j, u_j, lam_j)_{j=1..N-2}, x_{N-1}, u_{N-1}]`` keeps the
    symmetric indefinite KKT matrix ``[[H, C^T], [C, 0]]`` banded (half-bandwidth 6); one
    LAPACK banded LU (gbsv, partial pivoting) solves it. The state is feasible (c = 0) and
    lambda is the adjoint, so the right-hand side is ``-[0, dJ/du, 0]``.
    """
    n = d.nodes
    h2 = 0.5 * d.h
    _, A = dynamics_jacobian(traj.x, traj.u, d.table)
    rows, cols, iu, ix, _, size = d.kkt_pattern
    eye = np.eye(3)
    blk_next = (eye - h2 * A[1:]).ravel()  # c_i w.r.t. x_{i+1}
    blk_prev = (-(eye + h2 * A[1:-1])).ravel()  # c_i w.r.t. x_i, i >= 1
    coup = np.full(n - 1, h2)  # c_i w.r.t. u_i and u_{i+1}: -h/2 df/du = (0, h/2, 0)
    vals = np.concatenate(
        [H[1:].ravel(), d.w, blk_next, blk_next, blk_prev, blk_prev, coup, coup, coup, coup]
    )
    kl = ku = 6
    ab = np.zeros((2 * kl + ku + 1, size))
    ab[kl + ku + rows - cols, cols] = vals
    rhs = np.zeros(size)
    rhs[iu] = -grad
    sol = _band_solve(ab, kl, ku, rhs)
    dx = np.zeros((n, 3))
    dx[1:] = sol[ix[1:]]
    return sol[iu], dx
