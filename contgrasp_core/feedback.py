"""Feedback control of continuum grasping (paper Sec. V-B, Prop. 1, appendix).

The law (eq. dynamic_feedback) ``u = -EI(-mu1 cos(alpha) + (rho - mu2) sin(alpha))`` and its
static curvature form (eq. curvature_feedback) ``kappa = -mu1 cos(alpha) + (rho - mu2) sin(alpha)``
are **not dimensionally homogeneous**: ``mu1`` is dimensionless, ``rho - mu2`` is a length and the
result is a curvature. Their numerical value therefore depends on the length unit in which the
law is evaluated. The paper's gains (``mu1 = 1`` and the adaptive ``mu2`` of the appendix) are
meant in centimetres, so every function here takes ``length_unit`` (metres per law unit) with
the default :data:`CENTIMETRE` = 0.01. Inputs and outputs are SI (metres, 1/m, N m); the gain
``mu2`` is given *in law units* (cm by default), exactly as the paper writes it. Conversion to
SI happens here, at the boundary. (Evaluated with ``length_unit=1`` on metre inputs the same
gains give a static closed loop whose equilibrium has ``rho < 0``: infeasible.)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Union

import numpy as np
from scipy.integrate import solve_ivp

from contgrasp_core.errors import InvalidParameterError

__all__ = [
    "CENTIMETRE",
    "ClosedLoopKinematics",
    "adaptive_mu2",
    "curvature_feedback",
    "feedback_couple",
    "feedback_couple_gradient",
    "equilibrium_distance",
    "lyapunov",
    "lyapunov_rate",
    "closed_loop_kinematics",
]

CENTIMETRE = 0.01
"""Metres per centimetre: the paper's length unit for the feedback gains."""

ArrayLike = Union[float, np.ndarray]
Gain = Union[float, np.ndarray, Callable[[np.ndarray], np.ndarray]]


def _check_unit(length_unit: float) -> float:
    if not (np.isfinite(length_unit) and length_unit > 0):
        raise InvalidParameterError(
            f"length_unit must be a finite positive number of metres per law unit, got {length_unit!r}"
        )
    return float(length_unit)


def adaptive_mu2(
    radius: ArrayLike, object_radius: float, *, length_unit: float = CENTIMETRE
) -> np.ndarray:
    """Adaptive gain ``mu2(s) = r(s) - 1/(r_obj + r(s))`` of the paper's appendix, in law units.

    Obtained from eq. dvds with ``rho_d = r(s)`` and ``kbar = 1/r_obj``, so that the
    equilibrium contact distance (eq. quadratic) equals the local arm radius.

    ``radius`` and ``object_radius`` are in metres; the result is in law units (cm by default).
    """
    lu = _check_unit(length_unit)
    r = np.asarray(radius, dtype=float)
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise InvalidParameterError("radius must be finite and > 0 (metres)")
    if not (np.isfinite(object_radius) and object_radius > 0):
        raise InvalidParameterError(f"object_radius must be finite and > 0 metres, got {object_radius!r}")
    r_u = r / lu
    return r_u - 1.0 / (object_radius / lu + r_u)


def curvature_feedback(
    rho: ArrayLike,
    alpha: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> np.ndarray:
    """Closed-loop curvature (eq. curvature_feedback), in 1/m.

    ``kappa_u = -mu1 cos(alpha) + (rho_u - mu2) sin(alpha)`` is evaluated in law units
    (``rho_u = rho / length_unit``; ``mu2`` already in law units) and converted to SI,
    ``kappa = kappa_u / length_unit``. ``rho`` in metres; gains scalar or per arclength.
    """
    lu = _check_unit(length_unit)
    rho = np.asarray(rho, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    kappa_u = -np.asarray(mu1, dtype=float) * np.cos(alpha) + (rho / lu - np.asarray(mu2, dtype=float)) * np.sin(alpha)
    return kappa_u / lu


def feedback_couple(
    rho: ArrayLike,
    alpha: ArrayLike,
    bending_stiffness: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> np.ndarray:
    """Internal couple control (eq. dynamic_feedback), in N m.

    ``u = -EI (-mu1 cos(alpha) + (rho - mu2) sin(alpha))`` with the bracket evaluated in law
    units and converted to 1/m, so ``u = -EI * curvature_feedback(...)``; ``EI`` in N m^2.
    It enters the moment balance (eq. dynamics) as ``u_s``; the total couple is ``EI kappa + u``.
    """
    ei = np.asarray(bending_stiffness, dtype=float)
    if np.any(~np.isfinite(ei)) or np.any(ei <= 0):
        raise InvalidParameterError("bending_stiffness EI must be finite and > 0 (N m^2)")
    return -ei * curvature_feedback(rho, alpha, mu1, mu2, length_unit=length_unit)


def feedback_couple_gradient(
    rho: ArrayLike,
    alpha: ArrayLike,
    bending_stiffness: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> tuple[np.ndarray, np.ndarray]:
    """Partial derivatives of eq. dynamic_feedback: ``du/drho = -EI sin(alpha) / l^2`` (N m/m)
    and ``du/dalpha = -EI (mu1 sin(alpha) + (rho/l - mu2) cos(alpha)) / l`` (N m/rad), with
    ``l`` the law's length unit."""
    lu = _check_unit(length_unit)
    ei = np.asarray(bending_stiffness, dtype=float)
    rho, alpha = np.asarray(rho, dtype=float), np.asarray(alpha, dtype=float)
    sa, ca = np.sin(alpha), np.cos(alpha)
    dk_da = (np.asarray(mu1, dtype=float) * sa + (rho / lu - np.asarray(mu2, dtype=float)) * ca) / lu
    dk_dr = sa / lu**2
    return -ei * dk_dr, -ei * dk_da


def _check_prop1(kbar: float, mu2: float) -> None:
    if not np.isfinite(kbar) or kbar < 0:
        raise InvalidParameterError(f"object curvature kbar must be finite and >= 0 (Prop. 1), got {kbar!r}")
    if not np.isfinite(mu2) or mu2 <= -kbar:
        raise InvalidParameterError(f"mu2 must be > -kbar = {-kbar!r} (Prop. 1), got {mu2!r}")


def equilibrium_distance(kbar: float, mu2: float, *, length_unit: float = 1.0) -> float:
    """Desired contact distance ``rho_d``: the admissible root of eq. quadratic (Prop. 1).

    ``kbar rho^2 + (1 - mu2 kbar) rho - (mu2 + kbar) = 0`` in law units. For ``kbar > 0`` and
    ``mu2 > -kbar`` the roots have negative product, so exactly one is positive; for
    ``kbar = 0`` the root is ``mu2`` (which must be > 0). ``kbar`` in 1/m and ``mu2`` in law
    units; result in metres. With the default ``length_unit=1`` everything is in one
    consistent (e.g. dimensionless) unit, as in Prop. 1.
    """
    lu = _check_unit(length_unit)
    k = float(kbar) * lu
    _check_prop1(k, float(mu2))
    if k == 0.0:
        return float(mu2) * lu
    b = 1.0 - mu2 * k
    c = -(mu2 + k)
    disc = np.sqrt(b * b - 4.0 * k * c)  # = sqrt((1 + mu2 k)^2 + 4 k^2) > 0
    # numerically stable positive root
    root = (-b + disc) / (2.0 * k) if b <= 0 else (2.0 * -c) / (b + disc)
    return float(root) * lu


def lyapunov(rho: ArrayLike, alpha: ArrayLike, mu2: float, kbar: float) -> np.ndarray:
    """Lyapunov function of Prop. 1 (appendix), in consistent units:

    ``V = -ln(sin alpha) + (rho - mu2)^2 / 2 - ln(1 + rho kbar)``.
    """
    rho = np.asarray(rho, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    return -np.log(np.sin(alpha)) + 0.5 * (rho - mu2) ** 2 - np.log1p(rho * kbar)


def lyapunov_rate(alpha: ArrayLike, mu1: float) -> np.ndarray:
    """``dV/ds = -mu1 cos^2(alpha) / sin(alpha)`` along the closed loop (Prop. 1 proof)."""
    alpha = np.asarray(alpha, dtype=float)
    return -mu1 * np.cos(alpha) ** 2 / np.sin(alpha)


@dataclass(frozen=True)
class ClosedLoopKinematics:
    """Closed-loop kinematics on an arclength grid (SI): ``s``, ``rho``, ``alpha``, ``kappa``
    (feedback curvature, 1/m), ``s_o`` (object arclength travelled from its start value)."""

    s: np.ndarray
    rho: np.ndarray
    alpha: np.ndarray
    kappa: np.ndarray
    s_o: np.ndarray


def _as_profile(g: Gain, name: str) -> Callable[[float], float]:
    if callable(g):
        return lambda s: float(np.asarray(g(np.asarray(s))))  # type: ignore[misc]
    arr = np.asarray(g, dtype=float)
    if arr.ndim == 0:
        v = float(arr)
        return lambda s: v
    raise InvalidParameterError(f"{name} must be a scalar or a callable of s (arrays: pass np.interp)")


def closed_loop_kinematics(
    rho0: float,
    alpha0: float,
    s: np.ndarray,
    mu1: Gain,
    mu2: Gain,
    object_curvature: Union[float, Callable[[float], float]],
    *,
    length_unit: float = CENTIMETRE,
    s_o0: float = 0.0,
    rtol: float = 1e-9,
    atol: float = 1e-12,
) -> ClosedLoopKinematics:
    """Integrate eq. rho_alpha_2 with the feedback curvature eq. curvature_feedback.

    ``drho/ds = -cos(alpha)``, ``dalpha/ds = -kappa + kappa_o sin(alpha) / (1 + rho kappa_o)``,
    ``ds_o/ds = sin(alpha) / (1 + rho kappa_o)`` (eq. object_speed), with
    ``kappa = curvature_feedback(rho, alpha, mu1(s), mu2(s))``. ``object_curvature`` is a constant
    (1/m) or a function of the object arclength ``s_o`` (m). Gains may be scalars or callables of
    ``s`` (m); ``mu2`` in law units. Raises :class:`InvalidParameterError` for a start outside
    the valid region (rho > 0, 0 < alpha < pi).
    """
    lu = _check_unit(length_unit)
    s = np.asarray(s, dtype=float)
    if s.ndim != 1 or s.size < 2 or np.any(np.diff(s) <= 0):
        raise InvalidParameterError("s must be a strictly increasing 1-D grid with >= 2 points")
    if not (rho0 > 0 and 0 < alpha0 < np.pi):
        raise InvalidParameterError(f"need rho0 > 0 and 0 < alpha0 < pi, got rho0={rho0}, alpha0={alpha0}")
    m1 = _as_profile(mu1, "mu1")
    m2 = _as_profile(mu2, "mu2")
    ko = (lambda so: float(object_curvature)) if not callable(object_curvature) else object_curvature

    def rhs(si: float, y: np.ndarray) -> np.ndarray:
        rho, alpha, so = y
        k_o = float(ko(so))
        den = 1.0 + rho * k_o
        kap = float(curvature_feedback(rho, alpha, m1(si), m2(si), length_unit=lu))
        return np.array([-np.cos(alpha), -kap + k_o * np.sin(alpha) / den, np.sin(alpha) / den])

    sol = solve_ivp(rhs, (s[0], s[-1]), [rho0, alpha0, s_o0], t_eval=s, method="LSODA", rtol=rtol, atol=atol)
    if not sol.success:  # pragma: no cover - solver failure is reported, not hidden
        raise InvalidParameterError(f"closed-loop kinematics integration failed: {sol.message}")
    rho, alpha, so = sol.y
    kappa = np.array([curvature_feedback(r, a, m1(si), m2(si), length_unit=lu) for r, a, si in zip(rho, alpha, s, strict=True)])
    return ClosedLoopKinematics(s=s.copy(), rho=rho, alpha=alpha, kappa=kappa, s_o=so)
