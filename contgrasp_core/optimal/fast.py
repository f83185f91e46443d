"""Fast solver of the discretised eq. optimal_kappa: reduced-space Newton through the KKT system.

Each iteration (``docs/optimal.md`` has the derivation):

1. the exact discrete adjoint gives the gradient dJ/dkappa (including the dependence of
   kappa_o on the control through s_o) and the nodal costates p;
2. the Newton direction solves the banded KKT system of the Lagrangian with the exact
   Hessian (second derivatives of eq. rho_alpha_2 weighted by the costates); if that direction
   is not a descent direction (non-convex region) the Gauss-Newton Hessian is used instead,
   whose reduced Hessian is positive definite;
3. a backtracking (Armijo) line search on the reduced cost: every trial control is integrated
   (Newton on the whole trapezoidal trajectory, warm-started from the linearised prediction),
   so iterates always satisfy the dynamics; a singular trial (1 + rho kappa_o <= 0) is rejected.

Stopping rule: the discrete PMP residual ``max_s |kappa + p_2| <= tol`` (curvature units;
at that point the cost is optimal to about tol^2). State constraints: augmented Lagrangian
outer loop (multiplier update ``y <- max(0, y - mu q)``, ``mu <- 10 mu`` when violation
does not shrink 4x); when no constraint is active it ends after the first inner solve.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InvalidParameterError
from .discrete import (
    ForwardSolveError,
    PenaltyState,
    Trajectory,
    _constraint_values,
    adjoint,
    evaluate,
    kkt_newton_step,
    lagrangian_hessian_blocks,
    solve_states,
)
from .guess import initial_control
from .problem import GraspProblem, GraspResult, make_result

__all__ = ["solve"]

Array = NDArray[np.float64]


def solve(
    problem: GraspProblem,
    *,
    initial: Any = None,
    tol: float = 1e-9,
    max_iterations: int = 200,
    max_outer: int = 15,
    constraint_tol: float = 1e-8,
    hessian: str = "exact",
    coarse: int | None = -1,
) -> GraspResult:
    """Solve eq. optimal_kappa (discretised) by Newton's method on the KKT conditions.

    ``initial``: 'approach' (default), 'zero', N curvatures, or a previous GraspResult
    (warm start; its augmented-Lagrangian multipliers are reused when the grids match).
    ``tol``: stopping threshold on ``max |kappa + p_2|``. ``hessian``: 'exact' (Newton,
    quadratic convergence) or 'gauss-newton' (linear convergence, always convex).
    ``coarse``: mesh sequencing - for a cold start the problem is first solved on ``coarse``
    nodes (default -1: about N/8, at least 41; None or 0: off) and its solution, interpolated,
    starts the fine solve (the coarse solution is within O(h_coarse^2) of the fine one, so the
    fine Newton iterations start in their quadratic region).
    Returns a :class:`GraspResult` with ``history`` = cost, residual, step length and
    Hessian kind (1 exact, 0 Gauss-Newton) per fine iteration; ``history['coarse_iterations']``.
    """
    if not (np.isfinite(tol) and tol > 0.0):
        raise InvalidParameterError(f"tol must be > 0, got {tol!r}")
    if int(max_iterations) != max_iterations or max_iterations < 1:
        raise InvalidParameterError(f"max_iterations must be an integer >= 1, got {max_iterations!r}")
    if hessian not in ("exact", "gauss-newton"):
        raise InvalidParameterError(f"hessian must be 'exact' or 'gauss-newton', got {hessian!r}")
    t_start = time.perf_counter()
    d = problem.disc
    n = d.nodes
    n_coarse = max(41, n // 8) if coarse == -1 else int(coarse or 0)
    coarse_its = 0
    opts = dict(tol=tol, max_iterations=max_iterations, max_outer=max_outer, constraint_tol=constraint_tol, hessian=hessian)
    pen = PenaltyState.zero(n, problem.penalty)
    if isinstance(initial, GraspResult) or not 3 <= n_coarse < n // 2:
        u, guess = initial_control(problem, initial)
        if isinstance(initial, GraspResult) and initial.multipliers is not None and initial.multipliers.shape == (n, 4):
            pen = PenaltyState(initial.multipliers.copy(), max(problem.penalty, float(initial.problem.penalty)))
    else:
        cp = _coarsened(problem, n_coarse)
        u_c, guess_c = initial_control(cp, initial)
        # the coarse solution only seeds the fine solve: its discretisation error O(h_c^2) is far
        # above 1e-2, so solving it more tightly buys nothing
        pre = _newton(cp, u_c, guess_c, PenaltyState.zero(n_coarse, problem.penalty), **{**opts, "tol": max(tol, 1e-2)})
        coarse_its = pre.iterations
        t_c, t_f = cp.s / cp.s[-1], problem.s / problem.s[-1]
        u = np.interp(t_f, t_c, pre.traj.u)
        guess = np.stack([np.interp(t_f, t_c, v) for v in pre.traj.x.T], axis=-1)
    out = _newton(problem, u, guess, pen, **opts)
    wall = time.perf_counter() - t_start
    return make_result(
        problem,
        solver="fast",
        u=out.traj.u,
        x=out.traj.x,
        lam=out.lam,
        cost=out.traj.cost,
        penalty=out.traj.penalty,
        residual=out.residual,
        iterations=out.iterations,
        wall_time=wall,
        converged=out.converged,
        history={**{k: np.asarray(v) for k, v in out.history.items()}, "coarse_iterations": np.asarray(coarse_its)},
        multipliers=out.pen.y,
        message=out.message,
    )


@dataclass(frozen=True, eq=False)
class _NewtonOutcome:
    traj: Trajectory
    lam: Array
    pen: PenaltyState
    residual: float
    iterations: int
    converged: bool
    message: str
    history: dict[str, list[float]]


def _newton(
    problem: GraspProblem,
    u: Array,
    guess: Array | None,
    pen: PenaltyState,
    *,
    tol: float,
    max_iterations: int,
    max_outer: int,
    constraint_tol: float,
    hessian: str,
) -> _NewtonOutcome:
    """Augmented-Lagrangian outer loop around damped Newton iterations (module docstring)."""
    d = problem.disc
    n = d.nodes
    try:
        x = solve_states(d, u, guess)
    except ForwardSolveError as exc:
        raise InvalidParameterError(
            f"the initial curvature makes the contact kinematics singular ({exc}); give another initial guess"
        ) from exc
    hist: dict[str, list[float]] = {"cost": [], "residual": [], "step": [], "exact_hessian": []}
    iterations = 0
    converged = False
    message = ""
    prev_violation = np.inf
    lam = np.zeros((n - 1, 3))
    res = np.inf
    traj = evaluate(d, u, x, pen)
    for _outer in range(max_outer):
        traj = evaluate(d, traj.u, traj.x, pen)
        lam, grad = adjoint(d, traj, pen)
        res = float(np.max(np.abs(grad / d.w)))
        use_exact = hessian == "exact"
        inner_ok = False
        while iterations < max_iterations:
            if res <= tol:
                inner_ok = True
                break
            iterations += 1
            H = lagrangian_hessian_blocks(d, traj.x, lam, pen, gauss_newton=not use_exact)
            du, dx = kkt_newton_step(d, traj, lam, grad, H)
            slope = float(grad @ du)
            if not slope < 0.0 and use_exact:
                H = lagrangian_hessian_blocks(d, traj.x, lam, pen, gauss_newton=True)
                du, dx = kkt_newton_step(d, traj, lam, grad, H)
                slope = float(grad @ du)
                exact_used = 0.0
            else:
                exact_used = 1.0 if use_exact else 0.0
            step, new = _line_search(d, traj, du, dx, slope, pen)
            if new is None:
                if use_exact:
                    use_exact = False  # retry this iterate with the convex model
                    continue
                message = f"line search failed at iteration {iterations} (residual {res:.3g})"
                break
            if hessian == "exact":
                use_exact = True
            traj = new
            lam, grad = adjoint(d, traj, pen)
            res = float(np.max(np.abs(grad / d.w)))
            hist["cost"].append(traj.cost)
            hist["residual"].append(res)
            hist["step"].append(step)
            hist["exact_hessian"].append(exact_used)
        if not inner_ok:
            if not message:
                message = f"iteration limit {max_iterations} reached (residual {res:.3g} > tol {tol:.3g})"
            break
        q, _, _, _ = _constraint_values(d, traj.x)
        violation = float(np.max(np.maximum(0.0, -q)))
        y_new = np.maximum(0.0, pen.y - pen.mu * q)
        if violation <= constraint_tol and np.max(np.abs(y_new - pen.y)) <= constraint_tol * pen.mu:
            converged = True
            message = f"converged: residual {res:.3g} <= tol {tol:.3g}, constraint violation {violation:.3g}"
            break
        mu = pen.mu * (10.0 if violation > 0.25 * prev_violation else 1.0)
        prev_violation = violation
        pen = PenaltyState(y_new, mu)
    else:
        message = f"augmented-Lagrangian loop did not settle in {max_outer} rounds"
    return _NewtonOutcome(traj, lam, pen, res, iterations, converged, message, hist)


def _coarsened(problem: GraspProblem, nodes: int) -> GraspProblem:
    """The same problem on ``nodes`` grid points (profiles interpolated linearly)."""
    d = problem.disc
    s = np.linspace(0.0, float(d.s[-1]), nodes)
    h = float(s[1] - s[0])
    w = np.full(nodes, h)
    w[0] = w[-1] = 0.5 * h
    disc = replace(d, s=s, h=h, w=w, rho_d=np.interp(s, d.s, d.rho_d), alpha_d=np.interp(s, d.s, d.alpha_d))
    return replace(problem, disc=disc)


def _line_search(d, traj, du, dx, slope, pen):  # type: ignore[no-untyped-def]
    """Armijo backtracking on the reduced cost; returns (step, trajectory) or (0, None)."""
    f0 = traj.total
    t = 1.0
    while t >= 1e-10:
        u = traj.u + t * du
        try:
            x = solve_states(d, u, traj.x + t * dx)
        except ForwardSolveError:
            t *= 0.5
            continue
        new = evaluate(d, u, x, pen)
        if new.total <= f0 + 1e-4 * t * slope:
            return t, new
        if t == 1.0 and abs(slope) <= 1e-10 * (1.0 + abs(f0)) and new.total <= f0 + 1e-13 * (1.0 + abs(f0)):
            return t, new  # predicted decrease at rounding level: accept a non-increasing full step
        t *= 0.5
    return 0.0, None
