"""Optimal grasping configuration (paper Sec. III, the problem of eq. (9)).

* :func:`grasp_problem`, :func:`paper_problem`, :func:`problem_from_base` build a validated,
  discretised instance (:class:`GraspProblem`).
* :func:`solve` - the fast default solver: Newton on the KKT system of the discretised problem
  with the exact discrete adjoint gradient (including d kappa_o / d s_o).
* :func:`forward_backward` - the paper's forward-backward sweep (eq. (13)), kept as the
  reference baseline (eta = 1e-6, chi = 10 by default).
* :func:`gradient` - the exact gradient of the discretised cost (for checks and custom solvers).

Both solvers return a :class:`GraspResult`. See docs/optimal.md.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ContactValidityError
from .discrete import ForwardSolveError, PenaltyState, adjoint, evaluate, nodal_costates, solve_states
from .fast import solve
from .problem import (
    PAPER_SETTINGS,
    ConstraintStatus,
    GraspProblem,
    GraspResult,
    check_control,
    grasp_problem,
    paper_problem,
    problem_from_base,
)
from .forward_backward import forward_backward

__all__ = [
    "PAPER_SETTINGS",
    "ConstraintStatus",
    "GraspProblem",
    "GraspResult",
    "grasp_problem",
    "paper_problem",
    "problem_from_base",
    "solve",
    "forward_backward",
    "cost",
    "gradient",
]


def _states(problem: GraspProblem, u: NDArray[np.float64]) -> NDArray[np.float64]:
    try:
        return solve_states(problem.disc, u)
    except ForwardSolveError as exc:
        raise ContactValidityError(
            f"this curvature profile makes the contact kinematics singular: {exc}",
            s=float("nan"),
            condition="1 + rho kappa_o > 0",
        ) from exc


def cost(problem: GraspProblem, kappa: ArrayLike) -> float:
    """Discretised cost J(kappa) of eq. (9) (trapezoid rule, no constraint penalty)."""
    u = check_control(problem, kappa)
    x = _states(problem, u)
    return evaluate(problem.disc, u, x, PenaltyState.zero(problem.nodes, problem.penalty)).cost


def gradient(
    problem: GraspProblem, kappa: ArrayLike, *, frozen: bool = False, penalty: bool = False
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """(J, dJ/dkappa (N,), costates p (N, 3)) of the discretised cost, by the exact adjoint.

    ``frozen=True`` gives the paper's costates, eq. (12) (kappa_o treated as a given function of s),
    which is NOT the gradient of J unless kappa_o is constant along the boundary.
    ``penalty=True`` adds the state-constraint penalty (zero multipliers) to J and its gradient.
    """
    u = check_control(problem, kappa)
    d = problem.disc
    x = _states(problem, u)
    pen = PenaltyState.zero(problem.nodes, problem.penalty if penalty else 0.0)
    traj = evaluate(d, u, x, pen)
    lam, grad = adjoint(d, traj, pen, frozen=frozen)
    return traj.total, grad, nodal_costates(d, lam)
