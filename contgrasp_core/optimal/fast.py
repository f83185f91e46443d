"""Fast solver of the discretised eq. (9): Newton's method on the KKT conditions.

A cold start runs three stages: SQP steps on a coarse grid (about N/8 nodes) to seed the fine
grid; SQP steps on the fine grid, then feasibility restored exactly; reduced-space Newton
iterations with the exact discrete adjoint that certify the optimum (the discrete PMP residual
``max_s |kappa + p_2| <= tol``, or with ``cost_tol`` the Newton decrement) and finish if needed.
State constraints: an augmented-Lagrangian outer loop. Derivation and measurements:
docs/optimal.md, "Fast solver" and "Constraint handling".
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any, TypedDict

import numpy as np
from numpy.typing import NDArray

from .._validate import MAX_NODES, instance, integer, real
from ..errors import InvalidParameterError
from .discrete import (
    Discretisation,
    ForwardSolveError,
    KKTFactor,
    Linearisation,
    PenaltyState,
    SingularSystemError,
    Trajectory,
    _constraints,
    adjoint,
    evaluate,
    kkt_newton_step,
    kkt_resolve,
    kkt_solve,
    lagrangian_gradient,
    lagrangian_hessian_blocks,
    linearise,
    solve_states_linearised,
)
from .guess import initial_control, initial_states
from .problem import GraspProblem, GraspResult, make_result

__all__ = ["solve"]

COARSE_SWITCH = 3e-2
"""SQP switch on the coarse grid: its solution only seeds the fine solve (see :func:`_sqp_steps`);
the fine grid's first step changes J by 2-5e-2 J on the Fig. 2 problems anyway (the coarse-to-fine
discretisation difference), so tighter coarse solves buy nothing."""
FINE_SWITCH = 3e-5
"""SQP switch on the fine grid when only the residual tolerance ``tol`` is given."""
SQP_STEPS = 6
"""The most SQP steps on a grid (they contract quadratically from a good seed, or are given up)."""

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
    cost_tol: float | None = None,
    coarse_tol: float = 1.0,
) -> GraspResult:
    """Solve eq. (9) (discretised) by Newton's method on the KKT conditions.

    ``initial``: 'approach' (default), 'zero', N curvatures, or a previous GraspResult
    (warm start; its augmented-Lagrangian multipliers are reused when the grids match; no
    mesh sequencing). ``tol``: stopping threshold on ``max |kappa + p_2|``. ``cost_tol``: also
    stop when the Newton decrement predicts ``J - J* <= cost_tol |J|`` (module docstring).
    ``hessian``: 'exact' (Newton, quadratic convergence) or 'gauss-newton' (linear convergence,
    always convex) for the reduced Newton iterations.
    ``coarse``: mesh sequencing - for a cold start the problem is first solved on ``coarse``
    nodes (default -1: about N/8, at least 41; None or 0: off) by SQP steps (after damped Newton
    iterations down to the residual ``coarse_tol`` if the SQP steps do not contract from the
    guess); its solution, interpolated, starts SQP steps on the fine grid (the coarse solution is
    within O(h_coarse^2) of the fine one, so they start in Newton's quadratic region).
    Returns a :class:`GraspResult`; ``iterations`` counts fine-grid Newton steps (SQP and
    reduced), at most ``max_iterations``; ``history`` = cost and residual of the trajectory the reduced Newton iterations
    start from and after each of them (the fine SQP steps before them satisfy the dynamics only
    at their end: that end is the start), step length and Hessian kind (1 exact, 0
    Gauss-Newton) per reduced Newton iteration, ``sqp_steps`` (fine grid),
    ``coarse_sqp_steps`` and ``coarse_iterations`` (damped Newton on the coarse grid).
    """
    instance("problem", problem, GraspProblem)
    tol = real("tol", tol, lo=0.0, lo_open=True)
    if cost_tol is not None:
        cost_tol = real("cost_tol", cost_tol, lo=0.0, lo_open=True)
    max_iterations = integer("max_iterations", max_iterations, lo=1, hi=2**62)
    max_outer = integer("max_outer", max_outer, lo=1, hi=1000)
    constraint_tol = real("constraint_tol", constraint_tol, lo=0.0)
    coarse_tol = real("coarse_tol", coarse_tol, lo=0.0, lo_open=True)
    if coarse is not None:
        coarse = integer("coarse", coarse, lo=-1, hi=MAX_NODES)
    if not isinstance(hessian, str) or hessian not in ("exact", "gauss-newton"):
        raise InvalidParameterError(f"hessian must be 'exact' or 'gauss-newton', got {hessian!r}")
    t_start = time.perf_counter()
    d = problem.disc
    n = d.nodes
    n_coarse = max(41, n // 8) if coarse == -1 else int(coarse or 0)
    coarse_its = coarse_sqp = sqp_steps = 0
    opts: _NewtonOptions = dict(
        tol=tol,
        max_iterations=max_iterations,
        max_outer=max_outer,
        constraint_tol=constraint_tol,
        hessian=hessian,
        cost_tol=cost_tol,
    )
    pen = PenaltyState.zero(n, problem.penalty)
    start_traj: Trajectory | None = None
    chord: KKTFactor | None = None
    if isinstance(initial, GraspResult) or not 3 <= n_coarse < n // 2:
        u, guess = initial_control(problem, initial)
        if isinstance(initial, GraspResult) and initial.multipliers is not None and initial.multipliers.shape == (n, 4):
            pen = PenaltyState(initial.multipliers.copy(), max(problem.penalty, float(initial.problem.penalty)))
    else:
        cp = replace(problem, disc=d.coarsened(n_coarse))
        pen_c = PenaltyState.zero(n_coarse, problem.penalty)
        u_c, guess_c = initial_control(cp, initial)
        # states and adjoint of the initial guess (no iteration, for the penalty state pen_c the
        # SQP steps use), then SQP steps from there (exact Hessian only: the Gauss-Newton
        # option runs the damped iterations throughout)
        x_c, lin_c = initial_states(cp.disc, u_c, guess_c)
        s0 = evaluate(cp.disc, u_c, x_c, pen_c, lin_c)
        lam_s0, _ = adjoint(cp.disc, s0, pen_c)
        exact = hessian == "exact"
        u_c, x_c, lam_c, coarse_sqp, ok, _ = (
            _sqp_steps(cp, s0.u, s0.x, lam_s0, pen_c, cost_bound=s0.total, switch=COARSE_SWITCH, lin0=s0.lin)
            if exact
            else (s0.u, s0.x, lam_s0, 0, False, None)
        )
        if not ok:
            # globalise with the damped reduced Newton iterations, then SQP again; the coarse
            # solution only seeds the fine solve (its discretisation error O(h_c^2) is far above
            # coarse_tol), so the coarse problem is not solved more tightly than that
            coarse_opts: _NewtonOptions = {**opts, "tol": max(tol, coarse_tol), "cost_tol": None}
            pre = _newton(cp, u_c, x_c, pen_c, **coarse_opts)
            coarse_its = pre.iterations
            p0 = pre.traj
            u_c, x_c, lam_c, coarse_sqp, _, _ = (
                _sqp_steps(cp, p0.u, p0.x, pre.lam, pre.pen, cost_bound=p0.total, switch=COARSE_SWITCH, lin0=p0.lin)
                if exact
                else (p0.u, p0.x, pre.lam, 0, False, None)
            )
        t_c, t_f = cp.s / cp.s[-1], problem.s / problem.s[-1]
        u = np.interp(t_f, t_c, u_c)
        guess = np.stack([np.interp(t_f, t_c, v) for v in x_c.T], axis=-1)
        m_c, m_f = 0.5 * (t_c[1:] + t_c[:-1]), 0.5 * (t_f[1:] + t_f[:-1])  # lambda_i lives on step i
        lam = np.stack([np.interp(m_f, m_c, v) for v in lam_c.T], axis=-1)
        if exact:
            # after a step of predicted relative change p, Newton's quadratic convergence leaves a
            # decrement of about p^2 (measured constant <= 1): stop the SQP steps where the
            # certification below is expected to pass
            switch = FINE_SWITCH if cost_tol is None else min(np.sqrt(cost_tol), 1e-3)
            u, guess, _, sqp_steps, ok, last = _sqp_steps(problem, u, guess, lam, pen, switch=switch, keep_factor=cost_tol is not None,
                                                          max_steps=min(SQP_STEPS, max_iterations))
            if ok and last is not None:  # (last is set exactly when ok)
                start_traj, chord = last
    out = _newton(problem, u, guess, pen, **opts, start=start_traj, chord=chord, done=sqp_steps)
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
        history={
            **{k: np.asarray(v) for k, v in out.history.items()},
            "coarse_iterations": np.asarray(coarse_its),
            "coarse_sqp_steps": np.asarray(coarse_sqp),
            "sqp_steps": np.asarray(sqp_steps),
        },
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


class _NewtonOptions(TypedDict):
    """The keyword options :func:`solve` passes on to :func:`_newton`."""

    tol: float
    max_iterations: int
    max_outer: int
    constraint_tol: float
    hessian: str
    cost_tol: float | None


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
    cost_tol: float | None,
    start: Trajectory | None = None,
    chord: KKTFactor | None = None,
    done: int = 0,
) -> _NewtonOutcome:
    """Augmented-Lagrangian outer loop around damped Newton iterations (module docstring).

    ``start``: the trajectory of (u, guess) when it is already known to satisfy the dynamics
    (evaluated with ``pen``). ``chord``: KKT factors of a nearby point (the last fine SQP step);
    the first stopping check by the Newton decrement then uses them (a chord step, the step is
    not taken) and falls back to a new factorisation when the check does not pass. ``done``:
    the steps already taken towards ``max_iterations`` (the fine SQP steps); the outcome's
    ``iterations`` counts them too.
    """
    d = problem.disc
    n = d.nodes
    if start is not None:
        traj = start
    else:
        x, lin = initial_states(d, u, guess)
        traj = evaluate(d, u, x, pen, lin)
    hist: dict[str, list[float]] = {"cost": [], "residual": [], "step": [], "exact_hessian": []}
    iterations = done
    converged = False
    message = ""
    prev_violation = np.inf
    lam = np.zeros((n - 1, 3))
    res = np.inf
    for outer in range(max_outer):
        if outer:  # new multipliers / penalty weight
            traj = evaluate(d, traj.u, traj.x, pen, traj.lin)
        lam, grad = adjoint(d, traj, pen)
        res = float(np.max(np.abs(grad / d.w)))
        if not outer:  # the trajectory the iterations start from
            hist["cost"].append(traj.cost)
            hist["residual"].append(res)
        use_exact = hessian == "exact"
        inner_ok = False
        predicted: float | None = None
        while True:
            if res <= tol:  # (also after the last allowed iteration)
                inner_ok = True
                break
            if iterations >= max_iterations:
                break
            if chord is not None and cost_tol is not None and use_exact and not outer:
                # decrement with the factors of the last SQP step (no new factorisation)
                du, _, _ = kkt_resolve(d, chord, -grad, np.zeros((n, 3)), np.zeros((n - 1, 3)))
                slope = float(grad @ du)
                if 0.0 < -0.5 * slope <= cost_tol * abs(traj.total):
                    predicted = -0.5 * slope
                    inner_ok = True
                    break
            chord = None
            H = lagrangian_hessian_blocks(d, traj.x, lam, pen, gauss_newton=not use_exact, lin=traj.lin)
            du, dx = kkt_newton_step(d, traj, lam, grad, H)
            slope = float(grad @ du)
            if not slope < 0.0 and use_exact:
                H = lagrangian_hessian_blocks(d, traj.x, lam, pen, gauss_newton=True, lin=traj.lin)
                du, dx = kkt_newton_step(d, traj, lam, grad, H)
                slope = float(grad @ du)
                exact_used = 0.0
            else:
                exact_used = 1.0 if use_exact else 0.0
            if cost_tol is not None and exact_used and 0.0 < -0.5 * slope <= cost_tol * abs(traj.total):
                predicted = -0.5 * slope  # Newton decrement / 2: the predicted J - J*; step not taken
                inner_ok = True
                break
            iterations += 1
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
        q = _constraints(d, traj.x, traj.lin)
        violation = float(np.max(np.maximum(0.0, -q)))
        y_new = np.maximum(0.0, pen.y - pen.mu * q)
        if violation <= constraint_tol and np.max(np.abs(y_new - pen.y)) <= constraint_tol * pen.mu:
            converged = True
            if predicted is None:
                message = f"converged: residual {res:.3g} <= tol {tol:.3g}, constraint violation {violation:.3g}"
            else:
                message = (
                    f"converged: predicted cost error {predicted:.3g} <= cost_tol |J| (Newton decrement), "
                    f"residual {res:.3g}, constraint violation {violation:.3g}"
                )
            break
        mu = pen.mu * (10.0 if violation > 0.25 * prev_violation else 1.0)
        prev_violation = violation
        pen = PenaltyState(y_new, mu)
    else:
        message = f"augmented-Lagrangian loop did not settle in {max_outer} rounds"
    return _NewtonOutcome(traj, lam, pen, res, iterations, converged, message, hist)


def _sqp_steps(
    problem: GraspProblem,
    u: Array,
    x: Array,
    lam: Array,
    pen: PenaltyState,
    *,
    cost_bound: float = np.inf,
    switch: float = FINE_SWITCH,
    max_steps: int = SQP_STEPS,
    keep_factor: bool = False,
    lin0: Linearisation | None = None,
) -> tuple[Array, Array, Array, int, bool, tuple[Trajectory, KKTFactor | None] | None]:
    """Full Newton steps on the KKT conditions (SQP without line search) from (x, u, lambda),
    which need not satisfy the dynamics (e.g. the interpolated coarse solution): each step costs
    one linearisation and one KKT solve (:func:`kkt_solve`, the defects c in the right-hand
    side), with no forward integration and no adjoint.

    Runs until a step's predicted change of the Lagrangian, 1/2 |dL/d(x, u) . d|, is <=
    ``switch`` times the cost at the point it starts from (Newton's quadratic region), then
    restores c = 0 for the final control (trajectory Newton) and checks that its cost is below
    ``cost_bound``. The steps are only trusted while they contract (each predicted change at
    most half the previous one) and the linearisation stays regular (finite, 1 + rho kappa_o
    > 0); otherwise, or if the restoration fails, the starting point is returned with ``False``.
    Returns (u, x, lambda, steps, success, last), x satisfying the dynamics on success; ``last``
    is then (the evaluated trajectory of (u, x), the KKT factors of the last step if
    ``keep_factor`` else None), otherwise None. ``lin0``: the dynamics linearised at the
    starting (u, x) when the caller has them.
    """
    d = problem.disc
    u0, x0, lam0 = u, x, lam
    x = x.copy()
    x[0] = d.x0
    prev = np.inf
    for steps in range(1, max_steps + 1):
        if lin0 is not None and steps == 1:
            lin = lin0  # computed at the same (u, x): x[0] = x0 already
        else:
            lin = linearise(x, u, d.table)
        if not (np.all(np.isfinite(lin.f)) and np.all(lin.D > 0.0)):
            break
        Lu, Lx, c = lagrangian_gradient(d, lin, lam, pen)
        H = lagrangian_hessian_blocks(d, x, lam, pen, gauss_newton=False, lin=lin)
        try:
            if keep_factor:
                du, dx, dlam, factor = kkt_solve(d, lin, H, -Lu, -Lx, -c, keep_factor=True)
            else:
                du, dx, dlam = kkt_solve(d, lin, H, -Lu, -Lx, -c)
                factor = None
        except SingularSystemError:
            break
        predicted = 0.5 * abs(float(Lu @ du + np.sum(Lx[1:] * dx[1:])))
        if not predicted <= 0.5 * prev:
            break
        prev = predicted
        scale = abs(evaluate(d, u, x, pen, lin).total)
        u, x, lam = u + du, x + dx, lam + dlam
        if predicted <= switch * scale:
            try:
                x, lin = solve_states_linearised(d, u, x, march=False, chord=True)
            except ForwardSolveError:
                break
            traj = evaluate(d, u, x, pen, lin)
            if traj.total < cost_bound:
                return u, x, lam, steps, True, (traj, factor)
            break
    return u0, x0, lam0, 0, False, None


def _line_search(
    d: Discretisation, traj: Trajectory, du: Array, dx: Array, slope: float, pen: PenaltyState
) -> tuple[float, Trajectory | None]:
    """Armijo backtracking on the reduced cost; returns (step, trajectory) or (0, None)."""
    f0 = traj.total
    t = 1.0
    while t >= 1e-10:
        u = traj.u + t * du
        try:
            x, lin = solve_states_linearised(d, u, traj.x + t * dx, march=False)
        except ForwardSolveError:
            t *= 0.5
            continue
        new = evaluate(d, u, x, pen, lin)
        if new.total <= f0 + 1e-4 * t * slope:
            return t, new
        if t == 1.0 and abs(slope) <= 1e-10 * (1.0 + abs(f0)) and new.total <= f0 + 1e-13 * (1.0 + abs(f0)):
            return t, new  # predicted decrease at rounding level: accept a non-increasing full step
        t *= 0.5
    return 0.0, None
