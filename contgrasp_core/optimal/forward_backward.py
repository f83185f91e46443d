"""The paper's forward-backward sweep (Sec. III-A, the update eq. (13)), the reference baseline.

Every iteration integrates eq. (8) forward (the trapezoidal rule of :mod:`.discrete`, as the fast
solver), the costates backward from p(L) = 0 (the paper's eq. (12), ``gradient='paper'``, or the
exact discrete adjoint, ``gradient='exact'``), then updates ``kappa <- kappa + eta (-p_2 -
kappa)`` (paper defaults eta = 1e-6, chi = 10). Inadmissible iterates are counted, not errors;
a singular forward integration or a non-finite cost stops it. docs/optimal.md, "The paper's
forward-backward sweep".
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .._validate import instance, integer, real
from ..errors import InvalidParameterError
from .discrete import ForwardSolveError, PenaltyState, adjoint, evaluate, solve_states_linearised
from .guess import initial_control, initial_states
from .problem import GraspProblem, GraspResult, make_result

__all__ = ["forward_backward"]


def forward_backward(
    problem: GraspProblem,
    *,
    eta: float = 1e-6,
    max_iterations: int = 100_000,
    gradient: str = "paper",
    initial: Any = None,
    tol: float = 1e-6,
    target_cost: float | None = None,
    time_budget: float | None = None,
) -> GraspResult:
    """Run the forward-backward sweep of eq. (13).

    Stops when ``max |kappa + p_2| <= tol`` (with the costates of ``gradient``), when the cost
    reaches ``target_cost`` (used by the benchmark), after ``max_iterations`` or
    ``time_budget`` seconds, or when the forward integration becomes singular.
    ``result.history['cost']`` is the cost of every iterate (``history['residual']`` its
    residual); ``result.residual`` is the EXACT discrete PMP residual of the returned iterate
    and ``result.costates`` the costates the sweep used. ``result.constraints`` counts the
    inadmissible iterates.
    """
    instance("problem", problem, GraspProblem)
    eta = real("eta", eta, lo=0.0, lo_open=True)
    if not isinstance(gradient, str) or gradient not in ("paper", "exact"):
        raise InvalidParameterError(f"gradient must be 'paper' or 'exact', got {gradient!r}")
    max_iterations = integer("max_iterations", max_iterations, lo=0, hi=2**62)
    tol = real("tol", tol, lo=0.0, lo_open=True)
    if target_cost is not None:
        target_cost = real("target_cost", target_cost)
    if time_budget is not None:
        time_budget = real("time_budget", time_budget, lo=0.0, lo_open=True)
    frozen = gradient == "paper"
    t_start = time.perf_counter()
    d = problem.disc
    u, guess = initial_control(problem, initial)
    x, lin = initial_states(d, u, guess)
    pen = PenaltyState.zero(d.nodes, problem.penalty)
    costs: list[float] = []
    residuals: list[float] = []
    n_bad, first_bad, last_bad = 0, None, None
    converged = False
    message = f"iteration limit {max_iterations} reached"
    traj = evaluate(d, u, x, pen, lin)
    lam, grad = adjoint(d, traj, pen, frozen=frozen)
    k = 0
    while True:
        res = float(np.max(np.abs(grad / d.w)))
        costs.append(traj.cost)
        residuals.append(res)
        xs = traj.x
        if not (np.all(xs[:, 0] > 0.0) and np.all((xs[:, 1] > 0.0) & (xs[:, 1] < np.pi))):
            n_bad += 1
            first_bad = k if first_bad is None else first_bad
            last_bad = k
        if not np.isfinite(traj.total) or (k > 0 and traj.total > 1e6 * (1.0 + costs[0])):
            message = f"diverged at iteration {k} (cost {traj.total:.3g}); eta = {eta:.3g} is too large"
            break
        if res <= tol:
            converged = True
            message = f"converged: residual {res:.3g} <= tol {tol:.3g} after {k} iterations"
            break
        if target_cost is not None and traj.cost <= target_cost:
            converged = True
            message = f"reached target cost {target_cost:.8g} after {k} iterations"
            break
        if k >= max_iterations:
            break
        if time_budget is not None and time.perf_counter() - t_start > time_budget:
            message = f"time budget {time_budget:.3g} s exhausted after {k} iterations"
            break
        u_new = u - eta * grad / d.w  # eq. (13): kappa + eta (-p2 - kappa)
        try:
            x, lin = solve_states_linearised(d, u_new, traj.x)
        except ForwardSolveError as exc:
            message = f"forward integration singular at iteration {k + 1} ({exc}); eta = {eta:.3g} too large?"
            break
        u = u_new
        k += 1
        traj = evaluate(d, u, x, pen, lin)  # the linearisation of the forward solve serves the adjoint
        lam, grad = adjoint(d, traj, pen, frozen=frozen)
    lam_exact, grad_exact = adjoint(d, traj, pen) if frozen else (lam, grad)
    wall = time.perf_counter() - t_start
    return make_result(
        problem,
        solver=f"forward_backward[{gradient}]",
        u=traj.u,
        x=traj.x,
        lam=lam,
        cost=traj.cost,
        penalty=traj.penalty,
        residual=float(np.max(np.abs(grad_exact / d.w))),
        iterations=k,
        wall_time=wall,
        converged=converged,
        history={"cost": np.asarray(costs), "residual": np.asarray(residuals)},
        message=message,
        counts={"inadmissible_iterations": n_bad, "first_inadmissible": first_bad, "last_inadmissible": last_bad},
    )
