"""Initial controls for the optimal-grasp solvers (cold start and warm start).

* ``"approach"`` (default): a curvature profile from a simple stabilising law marched along
  the arm once: steer the contact angle towards ``alpha_ref = pi/2 - c (rho - rho_d)``
  (clipped to [0.3, pi - 0.3]) so that rho approaches rho_d, with
  ``kappa = kappa_o nu_o + k_alpha (alpha - alpha_ref)`` (the first term keeps alpha constant
  in eq. (8)). Gains: ``k_alpha = 20 / L``, ``c = 6 / L``. It only seeds the solvers.
* ``"zero"``: the straight arm kappa = 0 (may be singular for non-convex objects: a straight arm
  can pass a concave part at a distance beyond its focal distance, 1 + rho kappa_o <= 0).
* an array of N curvatures, or a previous :class:`GraspResult` (its curvature is
  interpolated in s/L onto the new grid) - the warm start used by quality maps.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidParameterError
from .discrete import ForwardSolveError, solve_states_linearised
from .problem import GraspProblem, GraspResult, check_control

__all__ = ["initial_control", "approach_control"]

Array = NDArray[np.float64]


def approach_control(problem: GraspProblem) -> tuple[Array, Array]:
    """Curvature from the stabilising approach law (module docstring), marched explicitly.

    Returns (kappa (N,), states (N, 3) of the explicit march, a guess for the implicit states).
    """
    d = problem.disc
    coeffs, step, length = d.table.scalar()
    c0, c1, c2, c3 = coeffs
    ncell = len(c0)
    L = float(d.s[-1])
    k_alpha, c_rho = 20.0 / L, 6.0 / L
    rho, alpha, sig = (float(v) for v in d.x0)
    rho_d, alpha_d = d.rho_d.tolist(), d.alpha_d.tolist()
    h = d.h
    h2 = 0.5 * h
    lo, hi = 0.3, math.pi - 0.3
    sin, cos = math.sin, math.cos
    last = ncell - 1
    n = d.nodes
    kaps: list[float] = []
    states: list[tuple[float, float, float]] = []
    # Heun's method on the approach law, the right-hand side written out twice (pure-Python
    # scalars: this loop is call-overhead bound)
    for i in range(n):
        sm = sig % length
        j = min(int(sm / step), last)
        t = sm - j * step
        k = ((c0[j] * t + c1[j]) * t + c2[j]) * t + c3[j]
        D = max(1.0 + rho * k, 0.05)
        g = sin(alpha) / D
        a_ref = min(max(alpha_d[i] - c_rho * (rho - rho_d[i]), lo), hi)
        kap = k * g + k_alpha * (alpha - a_ref)
        kaps.append(kap)
        states.append((rho, alpha, sig))
        if i + 1 == n:
            break
        f0, f1, f2 = -cos(alpha), -kap + k * g, g
        r1, a1, s1 = rho + h * f0, alpha + h * f1, sig + h * f2
        sm = s1 % length
        j = min(int(sm / step), last)
        t = sm - j * step
        k = ((c0[j] * t + c1[j]) * t + c2[j]) * t + c3[j]
        D = max(1.0 + r1 * k, 0.05)
        g = sin(a1) / D
        a_ref = min(max(alpha_d[i + 1] - c_rho * (r1 - rho_d[i + 1]), lo), hi)
        kap1 = k * g + k_alpha * (a1 - a_ref)
        rho += h2 * (f0 + -cos(a1))
        alpha += h2 * (f1 + (-kap1 + k * g))
        sig += h2 * (f2 + g)
    return np.array(kaps), np.array(states)


def initial_control(problem: GraspProblem, initial: Any) -> tuple[Array, Array | None]:
    """Resolve an ``initial`` argument (see module docstring) to N curvature samples.

    Returns (kappa, state guess or None).
    """
    n = problem.nodes
    if initial is None or (isinstance(initial, str) and initial == "approach"):
        return approach_control(problem)
    if isinstance(initial, str):
        if initial == "zero":
            return np.zeros(n), None
        raise InvalidParameterError(f"unknown initial guess {initial!r}; use 'approach', 'zero' or an array")
    if isinstance(initial, GraspResult):
        src = initial.s / initial.s[-1]
        t = problem.s / problem.s[-1]
        guess = np.stack([np.interp(t, src, v) for v in (initial.rho, initial.alpha, initial.s_o)], axis=-1)
        guess += problem.disc.x0 - guess[0]
        return np.interp(t, src, initial.kappa), guess
    return check_control(problem, initial, "initial curvature").copy(), None


def initial_states(d: Any, u: Array, guess: Array | None) -> tuple[Array, Any]:
    """States (and their linearisation) of the initial control, shared by both solvers.

    Raises InvalidParameterError when the initial curvature makes the kinematics singular.
    """
    try:
        return solve_states_linearised(d, u, guess)
    except ForwardSolveError as exc:
        raise InvalidParameterError(
            f"the initial curvature makes the contact kinematics singular ({exc}); start elsewhere (rho0, alpha0, s_o0: "
            "grasp's --rho0, --alpha0, --s-o0) or refine the grid (--nodes)"
        ) from exc
