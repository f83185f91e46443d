"""Feedback control of continuum grasping (paper Sec. V-B, Prop. 5.1, Appendices II and IV).

The law (eq. (19)) ``u = -EI(-mu1 cos(alpha) + (rho - mu2) sin(alpha))`` and its
static curvature form (eq. (20)) ``kappa = -mu1 cos(alpha) + (rho - mu2) sin(alpha)``
are **not dimensionally homogeneous**: ``mu1`` is dimensionless, ``rho - mu2`` is a length and the
result is a curvature. Their numerical value therefore depends on the length unit in which the
law is evaluated. The paper's gains (``mu1 = 1`` and the adaptive ``mu2`` of Appendix IV) are
meant in centimetres, so every function here takes ``length_unit`` (metres per law unit) with
the default :data:`CENTIMETRE` = 0.01. Inputs and outputs are SI (metres, 1/m, N m); the gain
``mu2`` is given *in law units* (cm by default), exactly as the paper writes it. Conversion to
SI happens here, at the boundary. (Evaluated with ``length_unit=1`` on metre inputs the same
gains give a static closed loop whose equilibrium has ``rho < 0``: infeasible.)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Union

import numpy as np

from contgrasp_core._validate import float_array, real
from contgrasp_core.errors import InvalidParameterError

__all__ = [
    "CENTIMETRE",
    "ClosedLoopKinematics",
    "adaptive_mu2",
    "curvature_feedback",
    "feedback_couple",
    "feedback_couple_gradient",
    "feedback_couple_and_gradient",
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
    return real("length_unit (metres per law unit)", length_unit, lo=0.0, lo_open=True)


def _finite_result(name: str, fn: Callable[[], Any]) -> Any:
    """Evaluate a pointwise formula (an array or a tuple of arrays); NaN/Inf inputs, overflow or
    a bad broadcast raise InvalidParameterError instead of returning non-finite values."""
    try:
        with np.errstate(all="ignore"):
            out = fn()
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"{name}: inputs must be numbers or arrays of matching shapes ({exc})") from exc
    except ArithmeticError as exc:  # Python-float overflow (e.g. length_unit**2)
        raise InvalidParameterError(f"{name} overflows: an input is too large ({exc})") from exc
    if not all(np.isfinite(v).all() for v in (out if isinstance(out, tuple) else (out,))):
        raise InvalidParameterError(
            f"{name} is not finite: an input is NaN or infinite, outside its domain, or too large"
        )
    return out


def _law(rho: ArrayLike, alpha: ArrayLike, mu1: ArrayLike, mu2: ArrayLike, lu: float) -> np.ndarray:
    """eq. (20) in 1/m (no checks)."""
    a = np.asarray(alpha, dtype=float)
    kappa_u = -np.asarray(mu1, dtype=float) * np.cos(a) + (np.asarray(rho, dtype=float) / lu - np.asarray(mu2, dtype=float)) * np.sin(a)
    return kappa_u / lu


def adaptive_mu2(
    radius: ArrayLike, object_radius: float, *, length_unit: float = CENTIMETRE
) -> np.ndarray:
    """Adaptive gain ``mu2(s) = r(s) - 1/(r_obj + r(s))`` of the paper's Appendix IV, in law units.

    Obtained from eq. (A-2) with ``rho_d = r(s)`` and ``kbar = 1/r_obj``, so that the
    equilibrium contact distance (eq. (21)) equals the local arm radius.

    ``radius`` and ``object_radius`` are in metres; the result is in law units (cm by default).
    """
    lu = _check_unit(length_unit)
    r = float_array("radius", radius)
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise InvalidParameterError("radius must be finite and > 0 (metres)")
    object_radius = real("object_radius (metres)", object_radius, lo=0.0, lo_open=True)
    return _finite_result("adaptive mu2", lambda: r / lu - 1.0 / (object_radius / lu + r / lu))


def curvature_feedback(
    rho: ArrayLike,
    alpha: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> np.ndarray:
    """Closed-loop curvature (eq. (20)), in 1/m.

    ``kappa_u = -mu1 cos(alpha) + (rho_u - mu2) sin(alpha)`` is evaluated in law units
    (``rho_u = rho / length_unit``; ``mu2`` already in law units) and converted to SI,
    ``kappa = kappa_u / length_unit``. ``rho`` in metres; gains scalar or per arclength.
    """
    lu = _check_unit(length_unit)
    return _finite_result("feedback curvature", lambda: _law(rho, alpha, mu1, mu2, lu))


def feedback_couple(
    rho: ArrayLike,
    alpha: ArrayLike,
    bending_stiffness: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> np.ndarray:
    """Internal couple control (eq. (19)), in N m.

    ``u = -EI (-mu1 cos(alpha) + (rho - mu2) sin(alpha))`` with the bracket evaluated in law
    units and converted to 1/m, so ``u = -EI * curvature_feedback(...)``; ``EI`` in N m^2.
    It enters the moment balance (eq. (17)) as ``u_s``; the total couple is ``EI kappa + u``.
    """
    lu = _check_unit(length_unit)
    ei = _stiffness(bending_stiffness)
    return _finite_result("feedback couple", lambda: -ei * _law(rho, alpha, mu1, mu2, lu))


def _stiffness(bending_stiffness: ArrayLike) -> np.ndarray:
    ei = float_array("bending_stiffness EI", bending_stiffness)
    if not (np.isfinite(ei).all() and (ei > 0).all()):
        raise InvalidParameterError("bending_stiffness EI must be finite and > 0 (N m^2)")
    return ei


def feedback_couple_gradient(
    rho: ArrayLike,
    alpha: ArrayLike,
    bending_stiffness: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> tuple[np.ndarray, np.ndarray]:
    """Partial derivatives of eq. (19): ``du/drho = -EI sin(alpha) / l^2`` (N m/m)
    and ``du/dalpha = -EI (mu1 sin(alpha) + (rho/l - mu2) cos(alpha)) / l`` (N m/rad), with
    ``l`` the law's length unit."""
    lu = _check_unit(length_unit)
    ei = _stiffness(bending_stiffness)

    def grad() -> tuple[np.ndarray, np.ndarray]:
        r, a = np.asarray(rho, dtype=float), np.asarray(alpha, dtype=float)
        sa, ca = np.sin(a), np.cos(a)
        dk_da = (np.asarray(mu1, dtype=float) * sa + (r / lu - np.asarray(mu2, dtype=float)) * ca) / lu
        dk_dr = sa / lu**2
        return -ei * dk_dr, -ei * dk_da

    return _finite_result("feedback couple gradient", grad)


def feedback_couple_and_gradient(
    rho: ArrayLike,
    alpha: ArrayLike,
    bending_stiffness: ArrayLike,
    mu1: ArrayLike,
    mu2: ArrayLike,
    *,
    length_unit: float = CENTIMETRE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`feedback_couple` and :func:`feedback_couple_gradient` in one pass: ``(u, du/drho,
    du/dalpha)``, the same operations (so the same values, bit for bit) with the inputs checked
    once and ``sin(alpha)``, ``cos(alpha)`` evaluated once (the controller's law every step)."""
    lu = _check_unit(length_unit)
    ei = _stiffness(bending_stiffness)

    def both() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r, a = np.asarray(rho, dtype=float), np.asarray(alpha, dtype=float)
        m1, m2 = np.asarray(mu1, dtype=float), np.asarray(mu2, dtype=float)
        sa, ca = np.sin(a), np.cos(a)
        offset = r / lu - m2
        u = -ei * ((-m1 * ca + offset * sa) / lu)
        return u, -ei * (sa / lu**2), -ei * ((m1 * sa + offset * ca) / lu)

    return _finite_result("feedback couple and its gradient", both)


def _check_prop1(kbar: float, mu2: float) -> None:
    if not np.isfinite(kbar) or kbar < 0:
        raise InvalidParameterError(f"object curvature kbar must be finite, >= 0 (Prop. 5.1), got {kbar!r}")
    if not np.isfinite(mu2) or mu2 <= -kbar:
        raise InvalidParameterError(f"mu2 must be > -kbar = {-kbar!r} (Prop. 5.1), got {mu2!r}")


def equilibrium_distance(kbar: float, mu2: float, *, length_unit: float = 1.0) -> float:
    """Desired contact distance ``rho_d``: the admissible root of eq. (21) (Prop. 5.1).

    ``kbar rho^2 + (1 - mu2 kbar) rho - (mu2 + kbar) = 0`` in law units. For ``kbar > 0`` and
    ``mu2 > -kbar`` the roots have negative product, so exactly one is positive; for
    ``kbar = 0`` the root is ``mu2`` (which must be > 0). ``kbar`` in 1/m and ``mu2`` in law
    units; result in metres. With the default ``length_unit=1`` everything is in one
    consistent (e.g. dimensionless) unit, as in Prop. 5.1.
    """
    lu = _check_unit(length_unit)
    mu2 = real("mu2", mu2)
    k = real("kbar", kbar) * lu
    _check_prop1(k, mu2)
    if k == 0.0:
        return _finite_result("equilibrium distance", lambda: np.float64(mu2) * lu).item()

    def root() -> np.ndarray:
        b = 1.0 - mu2 * k
        c = -(mu2 + k)
        disc = np.sqrt(np.float64(b) * b - 4.0 * k * c)  # = sqrt((1 + mu2 k)^2 + 4 k^2) > 0
        # numerically stable positive root
        return ((-b + disc) / (2.0 * k) if b <= 0 else (2.0 * -c) / (b + disc)) * lu

    return _finite_result("equilibrium distance", root).item()


def lyapunov(rho: ArrayLike, alpha: ArrayLike, mu2: float, kbar: float) -> np.ndarray:
    """Lyapunov function of Prop. 5.1 (Appendix II), in consistent units:

    ``V = -ln(sin alpha) + (rho - mu2)^2 / 2 - ln(1 + rho kbar)``.
    """

    def v() -> np.ndarray:
        r, a = np.asarray(rho, dtype=float), np.asarray(alpha, dtype=float)
        return -np.log(np.sin(a)) + 0.5 * (r - np.asarray(mu2, dtype=float)) ** 2 - np.log1p(r * np.asarray(kbar, dtype=float))

    return _finite_result("Lyapunov function V (needs sin(alpha) > 0 and 1 + rho kbar > 0)", v)


def lyapunov_rate(alpha: ArrayLike, mu1: float) -> np.ndarray:
    """``dV/ds = -mu1 cos^2(alpha) / sin(alpha)`` along the closed loop (proof of Prop. 5.1, Appendix II)."""

    def rate() -> np.ndarray:
        a = np.asarray(alpha, dtype=float)
        return -np.asarray(mu1, dtype=float) * np.cos(a) ** 2 / np.sin(a)

    return _finite_result("Lyapunov rate (needs sin(alpha) != 0)", rate)


_MAX_RHS_EVALUATIONS = 20_000  # about 0.5 s of right-hand sides; a well-posed loop needs < 3000


class _IntegrationAborted(Exception):
    """Raised inside the right-hand side to stop a hopeless integration."""


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
        return lambda s: float(np.asarray(g(np.asarray(s))))
    arr = float_array(name, g)
    if arr.ndim == 0:
        v = real(name, arr)
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
    """Integrate eq. (8) with the feedback curvature eq. (20).

    ``drho/ds = -cos(alpha)``, ``dalpha/ds = -kappa + kappa_o sin(alpha) / (1 + rho kappa_o)``,
    ``ds_o/ds = sin(alpha) / (1 + rho kappa_o)`` (eq. (7)), with
    ``kappa = curvature_feedback(rho, alpha, mu1(s), mu2(s))``. ``object_curvature`` is a constant
    (1/m) or a function of the object arclength ``s_o`` (m). Gains may be scalars or callables of
    ``s`` (m); ``mu2`` in law units. Raises :class:`InvalidParameterError` for a start outside
    the valid region (rho > 0, 0 < alpha < pi).
    """
    lu = _check_unit(length_unit)
    s = float_array("s", s)
    if s.ndim != 1 or s.size < 2 or not np.all(np.isfinite(s)) or np.any(np.diff(s) <= 0):
        raise InvalidParameterError("s must be a finite, strictly increasing 1-D grid with >= 2 points")
    rho0 = real("rho0", rho0, lo=0.0, lo_open=True)
    alpha0 = real("alpha0", alpha0, lo=0.0, hi=np.pi, lo_open=True, hi_open=True)
    s_o0 = real("s_o0", s_o0)
    rtol = real("rtol", rtol, lo=100 * np.finfo(float).eps, hi=0.1)
    atol = real("atol", atol, lo=0.0, lo_open=True)
    m1 = _as_profile(mu1, "mu1")
    m2 = _as_profile(mu2, "mu2")
    if callable(object_curvature):
        ko = object_curvature
    else:
        k_const = real("object_curvature", object_curvature)
        ko = lambda so: k_const  # noqa: E731
    evaluations = [0]

    def rhs(si: float, y: np.ndarray) -> np.ndarray:
        evaluations[0] += 1
        if evaluations[0] > _MAX_RHS_EVALUATIONS or not np.all(np.isfinite(y)):
            raise _IntegrationAborted
        rho, alpha, so = y
        k_o = float(ko(so))
        den = 1.0 + rho * k_o
        kap = float(curvature_feedback(rho, alpha, m1(si), m2(si), length_unit=lu))
        return np.array([-np.cos(alpha), -kap + k_o * np.sin(alpha) / den, np.sin(alpha) / den])

    from scipy.integrate import solve_ivp  # (here: the nodes never integrate; importing it costs them ~1 s)

    try:
        with np.errstate(all="ignore"):
            sol = solve_ivp(rhs, (s[0], s[-1]), [rho0, alpha0, s_o0], t_eval=s, method="LSODA", rtol=rtol, atol=atol)
    except _IntegrationAborted:
        raise InvalidParameterError(
            f"closed-loop kinematics integration failed: the state became non-finite or the problem is too stiff "
            f"(more than {_MAX_RHS_EVALUATIONS} evaluations); check the gains, rho0 and the object curvature"
        ) from None
    if not sol.success or not np.all(np.isfinite(sol.y)):
        raise InvalidParameterError(f"closed-loop kinematics integration failed: {sol.message}")
    rho, alpha, so = sol.y
    kappa = np.array([curvature_feedback(r, a, m1(si), m2(si), length_unit=lu) for r, a, si in zip(rho, alpha, s, strict=True)])
    return ClosedLoopKinematics(s=s.copy(), rho=rho, alpha=alpha, kappa=kappa, s_o=so)
