"""The optimal-grasp problem (eq. (9), minimise J over kappa) and the result both solvers return.

:func:`grasp_problem` validates the inputs and builds a :class:`GraspProblem`;
:func:`paper_problem` builds the paper's Fig. 2 settings (Sec. III-A); :func:`problem_from_base`
derives the initial contact state from an arm base pose by closest-point projection.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import MAX_NODES, float_array, instance, integer
from ..arm import Arm, ArmShape, BasePose, arclength_grid
from ..boundary import Boundary
from ..contact import check_state, initial_state, shape_from_contact
from ..errors import ContactValidityError, InvalidParameterError
from .discrete import CurvatureTable, Discretisation

if TYPE_CHECKING:
    from ..objects import ObjectSpec

__all__ = [
    "PAPER_SETTINGS",
    "GraspProblem",
    "ConstraintStatus",
    "GraspResult",
    "grasp_problem",
    "paper_problem",
    "problem_from_base",
    "constraint_status",
]

Array = NDArray[np.float64]
Profile = float | ArrayLike | Callable[[Array], ArrayLike]

PAPER_SETTINGS: dict[str, tuple[float, float]] = {
    "circle": (5.0, 1.6),
    "ellipse": (5.3, 1.8),
    "deformed": (4.7, 1.4),
}
"""Paper Sec. III-A: initial (rho0, alpha0) of each object of Fig. 2."""

DEFAULT_MARGINS = (1e-3, 1e-3, 1e-3)
DEFAULT_PENALTY = 1e3


@dataclass(frozen=True, eq=False)
class GraspProblem:
    """A discretised instance of eq. (9).

    ``boundary`` the object; ``arm`` its length and radius; ``disc`` the arrays the solvers use
    (grid, weights, initial state, desired profiles, chi, tabulated kappa_o);
    ``penalty`` the initial augmented-Lagrangian weight of the state constraints; ``object`` the
    :class:`~contgrasp_core.objects.ObjectSpec` the boundary was built from, when known
    (:func:`paper_problem`), which names it in results.
    """

    boundary: Boundary
    arm: Arm
    disc: Discretisation
    penalty: float = DEFAULT_PENALTY
    object: ObjectSpec | None = None

    @property
    def s(self) -> Array:
        return self.disc.s

    @property
    def nodes(self) -> int:
        return self.disc.nodes

    @property
    def rho0(self) -> float:
        return float(self.disc.x0[0])

    @property
    def alpha0(self) -> float:
        return float(self.disc.x0[1])

    @property
    def s_o0(self) -> float:
        return float(self.disc.x0[2])

    @property
    def chi(self) -> float:
        return self.disc.chi


def _finite(name: str, value: float) -> float:
    try:
        if np.ndim(value) != 0:
            raise TypeError("not a scalar")
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"{name} must be a number, got {value!r}") from exc
    if not np.isfinite(v):
        raise InvalidParameterError(f"{name} must be finite, got {value!r}")
    return v


def _profile(name: str, value: Profile, s: Array) -> Array:
    """Desired profile as an array on the grid: scalar, array of length N, or callable of s."""
    if callable(value):
        arr = float_array(f"desired profile {name}", value(s))
        arr = np.broadcast_to(arr, s.shape).copy() if arr.ndim == 0 else arr
    else:
        arr = float_array(f"desired profile {name}", value)
        if arr.ndim == 0:
            arr = np.full(s.shape, float(arr))
    if arr.shape != s.shape:
        raise InvalidParameterError(
            f"desired profile {name} has shape {arr.shape}; it must be a scalar, a callable of s, "
            f"or an array of length nodes = {len(s)}"
        )
    if not np.all(np.isfinite(arr)):
        raise InvalidParameterError(f"desired profile {name} contains NaN or infinite values")
    return arr


def grasp_problem(
    boundary: Boundary,
    *,
    rho0: float,
    alpha0: float,
    s_o0: float = 0.0,
    arm: Arm | None = None,
    nodes: int = 500,
    rho_d: Profile | None = None,
    alpha_d: Profile = 0.5 * np.pi,
    chi: float = 10.0,
    table_size: int = 4096,
    margins: tuple[float, float, float] = DEFAULT_MARGINS,
    penalty: float = DEFAULT_PENALTY,
) -> GraspProblem:
    """Build and validate an instance of eq. (9).

    ``arm`` defaults to the paper's tapered arm of length ``2 L_o / 3``; ``rho_d`` defaults to
    the arm radius r(s) (paper Sec. III-A) and ``alpha_d`` to pi/2. Profiles are scalars,
    arrays of length ``nodes`` or callables of s. ``margins`` are the distances kept from the
    boundaries of rho > 0, 0 < alpha < pi and 1 + rho kappa_o > 0 by the constraint penalty.
    Raises InvalidParameterError (bad chi, nodes, profiles) or ContactValidityError
    (rho0 <= 0, alpha0 outside (0, pi), 1 + rho0 kappa_o <= 0).
    """
    if not isinstance(boundary, Boundary):
        raise InvalidParameterError(f"boundary must be a Boundary, got {type(boundary).__name__}")
    rho0_, alpha0_, s_o0_ = _finite("rho0", rho0), _finite("alpha0", alpha0), _finite("s_o0", s_o0)
    if rho0_ <= 0.0:
        raise ContactValidityError(
            f"rho0 = {rho0_:.6g}: the initial contact distance must be > 0 (base outside the object)",
            s=0.0,
            condition="rho > 0",
        )
    if not 0.0 < alpha0_ < np.pi:
        raise ContactValidityError(
            f"alpha0 = {alpha0_:.6g}: the initial contact angle must lie in (0, pi) "
            "(object on the left of the arm)",
            s=0.0,
            condition="0 < alpha < pi",
        )
    check_state(boundary, rho0_, alpha0_, s_o0_)
    chi_ = _finite("chi", chi)
    if chi_ <= 0.0:
        raise InvalidParameterError(f"chi must be > 0 (weight of the tracking cost), got {chi!r}")
    nodes = integer("nodes", nodes, lo=3, hi=MAX_NODES)
    table_size = integer("table_size", table_size, lo=64, hi=1 << 22)
    pen = _finite("penalty", penalty)
    if pen <= 0.0:
        raise InvalidParameterError(f"penalty must be > 0, got {penalty!r}")
    try:
        m = tuple(_finite("margin", v) for v in margins)
    except TypeError as exc:
        raise InvalidParameterError(f"margins must be three numbers >= 0, got {margins!r}") from exc
    if len(m) != 3 or any(v < 0.0 for v in m):
        raise InvalidParameterError(f"margins must be three numbers >= 0, got {margins!r}")
    if arm is not None and not isinstance(arm, Arm):
        raise InvalidParameterError(f"arm must be an Arm or None, got {type(arm).__name__}")
    arm_ = Arm.paper_tapered(2.0 * boundary.length / 3.0) if arm is None else arm
    s = arclength_grid(arm_.length, nodes)
    h = float(s[1] - s[0])
    w = np.full(len(s), h)
    w[0] = w[-1] = 0.5 * h
    rho_d_ = _profile("rho_d", arm_.radius if rho_d is None else rho_d, s)
    # the tracking cost is about chi rho^2 L: keep it (and its derivatives) far from overflow
    size = max(rho0_, float(np.max(np.abs(rho_d_))), arm_.length)
    log_scale = math.log10(chi_) + 2.0 * math.log10(size) + math.log10(arm_.length)
    if log_scale > 250.0:
        raise InvalidParameterError(
            f"chi (max(rho0, |rho_d|, L))^2 L = 1e{log_scale:.0f} overflows the cost; choose a smaller chi or other length units"
        )
    disc = Discretisation(
        s=s,
        h=h,
        w=w,
        x0=np.array([rho0_, alpha0_, s_o0_]),
        rho_d=rho_d_,
        alpha_d=_profile("alpha_d", alpha_d, s),
        chi=chi_,
        table=CurvatureTable.from_boundary(boundary, int(table_size)),
        margins=(m[0], m[1], m[2]),
    )
    return GraspProblem(boundary=boundary, arm=arm_, disc=disc, penalty=pen)


MAX_TURNING = 1e9
"""Largest ``max |kappa| L`` of a control (radians the arm would turn): beyond it the
discretised dynamics overflow (and the contact leaves its admissible region anyway)."""


def check_control(problem: GraspProblem, kappa: ArrayLike, name: str = "kappa") -> Array:
    """``kappa`` as N finite curvature samples with ``max |kappa| L <= MAX_TURNING``."""
    instance("problem", problem, GraspProblem)
    u = float_array(name, kappa)
    if u.shape != (problem.nodes,) or not np.all(np.isfinite(u)):
        raise InvalidParameterError(f"{name} must be {problem.nodes} finite values, got shape {u.shape}")
    if np.max(np.abs(u)) * problem.arm.length > MAX_TURNING:
        raise InvalidParameterError(
            f"{name} is too large: max |kappa| L = {np.max(np.abs(u)) * problem.arm.length:.3g} > {MAX_TURNING:.0e}"
        )
    return u


def problem_from_base(boundary: Boundary, base: BasePose, **kwargs: Any) -> GraspProblem:
    """:func:`grasp_problem` with (rho0, alpha0, s_o0) from an arm base pose (closest point).

    Raises ContactValidityError if the base is inside the object or heads the wrong way.
    """
    rho0, alpha0, s_o0 = initial_state(boundary, base)
    return grasp_problem(boundary, rho0=rho0, alpha0=alpha0, s_o0=s_o0, **kwargs)


def paper_problem(obj: str | ObjectSpec, *, nodes: int = 500, **kwargs: Any) -> GraspProblem:
    """The paper's Sec. III-A optimal-grasp problem for an object.

    ``obj`` is an :class:`~contgrasp_core.objects.ObjectSpec` or its text (``'circle'``,
    ``'ellipse:6,3'``, ...; paper units). Settings: L = 2 L_o / 3, tapered radius L/20 -> L/200,
    rho_d = r(s), alpha_d = pi/2, chi = 10, s_o0 = 0 unless given; (rho0, alpha0) from
    :data:`PAPER_SETTINGS` for the three Fig. 2 objects, otherwise (the object's nominal radius,
    1.6), the paper circle's choice scaled to the object.
    """
    from ..objects import FIG2_SCALE, ObjectSpec

    spec = ObjectSpec.coerce(obj, FIG2_SCALE)
    paper = spec.shape in PAPER_SETTINGS and spec == ObjectSpec.parse(spec.shape, FIG2_SCALE)
    rho0, alpha0 = PAPER_SETTINGS[spec.shape] if paper else (spec.radius, PAPER_SETTINGS["circle"][1])
    kwargs.setdefault("rho0", rho0)
    kwargs.setdefault("alpha0", alpha0)
    return replace(grasp_problem(spec.boundary(), nodes=nodes, **kwargs), object=spec)


@dataclass(frozen=True)
class ConstraintStatus:
    """Admissibility of a solution (paper Sec. II-C) and, for iterative runs, of its iterates.

    ``ok``: rho > 0, 0 < alpha < pi and 1 + rho kappa_o > 0 at every node of the returned
    solution. ``inadmissible_iterations`` counts iterates that violated one of them;
    ``first_inadmissible`` / ``last_inadmissible`` are their iteration numbers (or None).
    """

    ok: bool
    min_rho: float
    min_alpha: float
    max_alpha: float
    min_speed_factor: float
    inadmissible_iterations: int = 0
    first_inadmissible: int | None = None
    last_inadmissible: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def constraint_status(problem: GraspProblem, x: Array, **counts: Any) -> ConstraintStatus:
    """Check the state constraints of eq. (9) at every node of ``x`` (N, 3)."""
    k, _, _ = problem.disc.table(x[:, 2])
    speed = 1.0 + x[:, 0] * k
    ok = bool(
        np.all(np.isfinite(x))
        and np.all(x[:, 0] > 0.0)
        and np.all((x[:, 1] > 0.0) & (x[:, 1] < np.pi))
        and np.all(speed > 0.0)
    )
    return ConstraintStatus(
        ok=ok,
        min_rho=float(np.min(x[:, 0])),
        min_alpha=float(np.min(x[:, 1])),
        max_alpha=float(np.max(x[:, 1])),
        min_speed_factor=float(np.min(speed)),
        **counts,
    )


@dataclass(frozen=True, eq=False)
class GraspResult:
    """Solution of eq. (9) from either solver.

    Arrays over the arm grid ``s``: ``kappa`` (control), ``rho``, ``alpha``, ``s_o`` (state,
    s_o unwrapped), ``costates`` (N, 3) = (p_1, p_2, p_s_o) (eq. (12) plus the s_o
    costate), ``kappa_o`` = kappa_o(s_o(s)) (tabulated curvature), ``shape`` (arm centreline
    r(s), theta(s) from ``r = gamma(s_o) - rho n``; computed lazily). ``cost`` is J of eq. (9) (trapezoid rule) without
    the constraint penalty (``penalty``). ``residual`` = max_s |kappa + p_2| (the discrete
    PMP residual, in curvature units). ``history`` holds the ``cost`` and ``residual`` of the
    starting iterate and after each iteration (the fast solver: each reduced Newton iteration;
    its ``sqp_steps`` SQP steps before them end in the starting iterate), and ``step`` for the
    fast solver: ``iterations - sqp_steps + 1`` entries.
    """

    problem: GraspProblem
    solver: str
    kappa: Array
    rho: Array
    alpha: Array
    s_o: Array
    costates: Array
    kappa_o: Array
    cost: float
    penalty: float
    residual: float
    iterations: int
    wall_time: float
    converged: bool
    constraints: ConstraintStatus
    history: dict[str, Array] = field(default_factory=dict)
    multipliers: Array | None = None
    message: str = ""

    @property
    def s(self) -> Array:
        return self.problem.s

    @cached_property
    def shape(self) -> ArmShape:
        """Arm centreline r(s) and tangent angle theta(s): ``r = gamma(s_o) - rho n(s_o)``,
        ``theta = phi(s_o) + pi/2 - alpha`` (computed on first access, not part of the solve)."""
        return shape_from_contact(self.s, self.rho, self.alpha, self.s_o, self.problem.boundary)

    def to_dict(self, arrays: bool = True) -> dict[str, Any]:
        """JSON-able summary (arrays as lists when ``arrays``); ``object`` is the problem's object by
        :meth:`~contgrasp_core.objects.ObjectSpec.text` (None for a bare boundary)."""
        p = self.problem
        out: dict[str, Any] = {
            "solver": self.solver,
            "object": None if p.object is None else p.object.text(),
            "cost": self.cost,
            "penalty": self.penalty,
            "residual": self.residual,
            "converged": self.converged,
            "iterations": self.iterations,
            "sqp_steps": int(self.history.get("sqp_steps", 0)),
            "wall_time_s": self.wall_time,
            "nodes": p.nodes,
            "arm_length": p.arm.length,
            "chi": p.chi,
            "rho0": p.rho0,
            "alpha0": p.alpha0,
            "s_o0": p.s_o0,
            "constraints_ok": self.constraints.ok,
            "constraints": self.constraints.to_dict(),
            "message": self.message,
        }
        if arrays:
            out.update(
                s=self.s.tolist(),
                kappa=self.kappa.tolist(),
                rho=self.rho.tolist(),
                alpha=self.alpha.tolist(),
                s_o=self.s_o.tolist(),
                kappa_o=self.kappa_o.tolist(),
                p1=self.costates[:, 0].tolist(),
                p2=self.costates[:, 1].tolist(),
                p3=self.costates[:, 2].tolist(),
                x=self.shape.r[:, 0].tolist(),
                y=self.shape.r[:, 1].tolist(),
                theta=self.shape.theta.tolist(),
                cost_history=self.history.get("cost", np.zeros(0)).tolist(),
                residual_history=self.history.get("residual", np.zeros(0)).tolist(),
            )
        return out


def make_result(
    problem: GraspProblem,
    *,
    solver: str,
    u: Array,
    x: Array,
    lam: Array,
    cost: float,
    penalty: float,
    residual: float,
    iterations: int,
    wall_time: float,
    converged: bool,
    history: dict[str, Array],
    multipliers: Array | None = None,
    message: str = "",
    counts: dict[str, Any] | None = None,
) -> GraspResult:
    """Assemble a :class:`GraspResult` (shape reconstruction, costates, constraint check)."""
    from .discrete import nodal_costates

    d = problem.disc
    k, _, _ = d.table(x[:, 2])
    return GraspResult(
        problem=problem,
        solver=solver,
        kappa=u.copy(),
        rho=x[:, 0].copy(),
        alpha=x[:, 1].copy(),
        s_o=x[:, 2].copy(),
        costates=nodal_costates(d, lam),
        kappa_o=k,
        cost=float(cost),
        penalty=float(penalty),
        residual=float(residual),
        iterations=int(iterations),
        wall_time=float(wall_time),
        converged=bool(converged),
        constraints=constraint_status(problem, x, **(counts or {})),
        history=history,
        multipliers=multipliers,
        message=message,
    )
