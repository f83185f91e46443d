"""Contact kinematics between the arm and the object boundary (paper Sec. II-C).

Three views of the same relative geometry: :func:`sense`, geometric sensing of the shadow point
s_o(s), rho and alpha (eq. (4)), delta (eq. (5)) and the contact set (Definition 1), the project's
one sensing function; :func:`integrate_contact`, the contact kinematics ODE (eqs. (7), (8))
driven by a curvature profile; :func:`shape_from_contact`, the reverse map to the arm shape.
The object is on the arm's LEFT; ``rho`` is signed (positive outside the object); valid states
have ``rho > 0``, ``0 < alpha < pi``, ``1 + rho kappa_o > 0``. docs/kinematics.md, "Contact".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import float_array, instance, real
from .arm import ArmShape, BasePose, curvature_spline
from .boundary import Boundary
from .errors import ContactValidityError, IntegrationError, InvalidParameterError
from .rod import _kernels


class ClosestPoints(Protocol):
    """The fields of a fast projection's closest points that sensing reads."""

    @property
    def foot(self) -> NDArray[np.float64]: ...
    @property
    def s_o(self) -> NDArray[np.float64]: ...
    @property
    def phi(self) -> NDArray[np.float64]: ...
    @property
    def kappa_o(self) -> NDArray[np.float64]: ...
    @property
    def signed_distance(self) -> NDArray[np.float64]: ...
    @property
    def normal_out(self) -> NDArray[np.float64]: ...


class Obstacle(Protocol):
    """A fast projection onto the object's boundary, as the rod engine keeps one
    (:class:`contgrasp_core.rod.obstacle.Obstacle`, which satisfies this): closest points of many
    points and, for a circle, the compiled closed form's ``(R, cx, cy)``. Named here by what
    sensing needs, so this module (below the rod engine) imports nothing of it."""

    @property
    def compiled_circle(self) -> tuple[float, float, float] | None: ...
    @property
    def length(self) -> float: ...
    def project(self, points: NDArray[np.float64]) -> ClosestPoints: ...

__all__ = [
    "ContactState",
    "ContactKinematics",
    "sense",
    "load_sensing",
    "shadow_geometry",
    "integrate_contact",
    "shape_from_contact",
    "initial_state",
    "base_pose",
    "check_state",
    "offset_curvature",
    "DEFAULT_CONTACT_TOL",
]

DEFAULT_CONTACT_TOL = 0.0
"""Default contact tolerance: in contact where ``delta >= -tol`` (Definition 1 exactly)."""


@dataclass(frozen=True)
class ContactState:
    """Geometric contact state along the arm (arrays over the arm grid ``s``), from :func:`sense`.

    ``rho`` (signed distance, > 0 outside the object) and ``alpha`` (in [-pi, pi)) of eq.
    (4); ``delta = r_arm - rho`` (eq. (5)); ``s_o`` the shadow point's
    arclength, unwrapped along the arm (continuous, may exceed L_o); ``foot`` = gamma(s_o) (n, 2);
    ``kappa_o`` the boundary curvature there; ``nu_o`` = sin(alpha) / (1 + rho kappa_o) (eq.
    (7)); ``foot_turn`` = kappa_o / (1 + rho kappa_o), the rate at which the foot's
    tangent angle phi(s_o) turns per unit tangential motion of the arm point (so
    ``nu_o kappa_o = sin(alpha) foot_turn``); ``normal_out`` = -n(s_o) (n, 2) the boundary's
    outward unit normal at the foot (the direction of ``r - gamma`` outside the object);
    ``in_contact`` is ``delta >= -tol`` (Definition 1); ``valid`` marks points inside the
    admissible region (rho > 0, 0 < alpha < pi, 1 + rho kappa_o > 0). ``nu_o`` and
    ``foot_turn`` are inf or meaningless where ``1 + rho kappa_o <= 0`` (not ``valid``).
    """

    s: NDArray[np.float64]
    rho: NDArray[np.float64]
    alpha: NDArray[np.float64]
    delta: NDArray[np.float64]
    s_o: NDArray[np.float64]
    foot: NDArray[np.float64]
    kappa_o: NDArray[np.float64]
    nu_o: NDArray[np.float64]
    foot_turn: NDArray[np.float64]
    normal_out: NDArray[np.float64]
    in_contact: NDArray[np.bool_]
    valid: NDArray[np.bool_]
    tol: float


@dataclass(frozen=True)
class ContactKinematics:
    """Solution of the contact kinematics ODE (eq. (8)) on the grid ``s``."""

    s: NDArray[np.float64]
    rho: NDArray[np.float64]
    alpha: NDArray[np.float64]
    s_o: NDArray[np.float64]


def _wrap_pi(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.mod(x + np.pi, 2.0 * np.pi) - np.pi


def _radius_array(radius: float | ArrayLike, n: int) -> NDArray[np.float64]:
    r = float_array("arm radius", radius)
    if r.shape not in ((), (n,)):
        raise InvalidParameterError(f"arm radius must be a scalar or one value per arm node ({n}), got shape {r.shape}")
    if r.shape != (n,):
        r = np.broadcast_to(r, (n,))  # (read only: delta = r - rho is a new array)
    if not (r.min() >= 0.0 and r.max() < np.inf):  # (NaN fails the first)
        raise InvalidParameterError("arm radius must be finite and >= 0 along the arm")
    return r


def _unwrap(s_o: NDArray[np.float64], length: float) -> NDArray[np.float64]:
    """``np.unwrap(s_o, period=length)`` (1-D), bit for bit: numpy's operations on the steps,
    written out so that the steps are taken once and the work is skipped when no step crosses
    the seam (unwrap adds nothing then). The rod wraps past ``s_o = 0`` in the paper run, so
    this runs in every sensing; numpy's general version costs twice as much."""
    if len(s_o) < 2:
        return s_o
    dd = np.diff(s_o)
    size = np.abs(dd)
    if not np.any(size >= 0.5 * length):
        return s_o
    half = length / 2  # (numpy: discont = interval_high = period / 2)
    ddmod = np.mod(dd + half, length) - half
    np.copyto(ddmod, half, where=(ddmod == -half) & (dd > 0))  # a step of exactly +period/2 stays
    ph_correct = ddmod - dd
    np.copyto(ph_correct, 0, where=size < half)
    out = s_o.copy()
    out[1:] = s_o[1:] + ph_correct.cumsum()
    return out


def shadow_geometry(
    points: NDArray[np.float64], angles: NDArray[np.float64], obstacle: Obstacle
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``rho``, ``alpha``, ``kappa_o``, ``foot_turn`` and ``normal_out`` of :func:`sense` (the
    same operations, so the same bits) of the points (n, 2) with tangent angles (n,), and
    nothing else: no input checks, no ``s_o``, ``delta`` or contact set. For the feedback law's
    first-order hold inside the rod's Newton iterations
    (:class:`~contgrasp_core.control.HeldExpansion`), which senses its own well-formed arrays
    several times per step and reads only these. Against a circle (kernels enabled) the same
    operations run in one compiled loop (:func:`contgrasp_core.rod._kernels.circle_shadow_geometry`)."""
    circle = obstacle.compiled_circle
    if circle is not None:
        return _kernels.circle_shadow_geometry(_kernels.f64(points), _kernels.f64(angles), *circle)
    proj = obstacle.project(points)
    rho = proj.signed_distance
    kappa_o = proj.kappa_o
    with np.errstate(divide="ignore", invalid="ignore"):
        foot_turn = kappa_o / (1.0 + rho * kappa_o)
    return rho, _wrap_pi(proj.phi + 0.5 * np.pi - angles), kappa_o, foot_turn, proj.normal_out


def sense(
    shape: ArmShape,
    boundary: Boundary | Obstacle,
    radius: float | ArrayLike,
    *,
    tol: float = DEFAULT_CONTACT_TOL,
) -> ContactState:
    """Geometric sensing of the contact state (:class:`ContactState`) of an arm shape.

    Vectorised over the arm's arclength: one closest-point projection of all the points
    ``shape.r``, then eq. (4) with the closest boundary point as shadow point
    (``rho`` = signed distance, ``alpha = phi(s_o) + pi/2 - theta`` wrapped to [-pi, pi)),
    eq. (5) (``delta = r_arm - rho``, ``radius`` a scalar or one value per point), eq.
    (7) (``nu_o``, ``foot_turn``) and Definition 1 with tolerance ``tol``
    (``in_contact = delta >= -tol``).

    ``boundary`` selects the projection, and this is the only place sensing calls it (with
    :func:`shadow_geometry`, the same operations on the subset of fields the feedback's Newton
    iterations read):

    * a :class:`~contgrasp_core.boundary.Boundary` - :meth:`Boundary.project`, Newton's method
      on the curve from several candidates, converged to rounding (the library, the sampled
      loop of :mod:`contgrasp_core.rod.session` and the ROS boundary sensor);
    * an :class:`~contgrasp_core.rod.obstacle.Obstacle` - its fast projection, analytic for
      circles and one osculating-circle Newton step from a table otherwise (about 1e-10 of the
      object size; the rod's continuous loop; inside every implicit step through
      :func:`shadow_geometry`).

    The two are different computations of the same closest point (they agree to rounding on
    circles and to ~1e-10 elsewhere); each caller keeps the one it has always used, so the
    sampled ROS loop and its core twin call this function on the same arrays and agree bitwise.
    """
    instance("shape", shape, ArmShape)
    if not isinstance(boundary, Boundary) and not (callable(getattr(boundary, "project", None))
                                                   and hasattr(type(boundary), "compiled_circle")):
        raise InvalidParameterError(f"boundary must be a Boundary or an Obstacle, got {type(boundary).__name__}")
    tol = real("contact tolerance", tol, lo=0.0)
    r = float_array("arm shape r", shape.r)
    theta = float_array("arm shape theta", shape.theta)
    if r.ndim != 2 or r.shape[1] != 2 or theta.shape != (len(r),) or len(r) == 0:
        raise InvalidParameterError(
            f"arm shape needs r of shape (n, 2) and theta of shape (n,), got {r.shape}, {theta.shape}"
        )
    ss = float_array("arm shape s", shape.s)
    if ss.shape != theta.shape:
        raise InvalidParameterError(f"arm shape needs s of shape {theta.shape}, got {ss.shape}")
    # a finite sum has finite terms; only on overflow (|values| ~ 1e308) check one by one
    with np.errstate(over="ignore", invalid="ignore"):
        total = r.sum() + theta.sum() + ss.sum()
    if not np.isfinite(total) and not (
        np.all(np.isfinite(r)) and np.all(np.isfinite(theta)) and np.all(np.isfinite(ss))
    ):
        raise InvalidParameterError("arm shape contains NaN or infinite values")
    rad = _radius_array(radius, len(r))
    if _kernels.ENABLED and isinstance(boundary, Boundary) and boundary.kind == "circle" and len(r):
        # the same operations in one compiled pass (the sensing of every step of the paper run)
        c = boundary.params["center"]
        s_o, rho, alpha, delta, foot, kappa_o, nu_o, foot_turn, normal_out = _kernels.circle_sense(
            _kernels.f64(r), _kernels.f64(theta), _kernels.f64(rad), float(boundary.params["R"]), float(c[0]),
            float(c[1]), float(boundary.length))
        one_plus = 1.0 + rho * kappa_o
    else:
        proj = boundary.project(r)
        s_o = _unwrap(proj.s_o, boundary.length)
        rho = proj.signed_distance
        alpha = _wrap_pi(proj.phi + 0.5 * np.pi - theta)
        kappa_o = proj.kappa_o
        one_plus = 1.0 + rho * kappa_o
        with np.errstate(divide="ignore", invalid="ignore"):
            nu_o = np.sin(alpha) / one_plus
            foot_turn = kappa_o / one_plus
        delta = rad - rho
        foot, normal_out = proj.foot, proj.normal_out
    valid = (rho > 0.0) & (alpha > 0.0) & (alpha < np.pi) & (one_plus > 0.0)
    return ContactState(
        s=ss,
        rho=rho,
        alpha=alpha,
        delta=delta,
        s_o=s_o,
        foot=foot,
        kappa_o=kappa_o,
        nu_o=nu_o,
        foot_turn=foot_turn,
        normal_out=normal_out,
        in_contact=delta >= -tol,
        valid=valid,
        tol=float(tol),
    )


def load_sensing() -> None:
    """Load the compiled sensing of :func:`sense` now (numba and its on-disk cache, ~0.3 s on
    first use in a process) by sensing a two-node arm against a unit circle once. The ROS
    boundary sensor calls it at start-up: in lock-step the whole loop waits for its first
    contact state, so paying this at the run's first state would cost the run that much."""
    from .boundary import circle

    sense(ArmShape(s=np.array([0.0, 1.0]), r=np.array([[2.0, 0.0], [2.0, 1.0]]), theta=np.array([0.5 * np.pi] * 2)),
          circle(1.0), 0.0)


def check_state(boundary: Boundary, rho: float, alpha: float, s_o: float, *, s: float = 0.0) -> None:
    """Raise ContactValidityError unless (rho, alpha, s_o) is an admissible contact state."""
    instance("boundary", boundary, Boundary)
    try:
        if any(np.ndim(v) != 0 for v in (rho, alpha, s_o)):
            raise TypeError("not scalars")
        vals = np.array([float(rho), float(alpha), float(s_o)])
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"contact state (rho, alpha, s_o) must be three numbers, got {(rho, alpha, s_o)!r}") from exc
    rho, alpha, s_o = (float(v) for v in vals)
    s = real("s", s)
    if not np.all(np.isfinite(vals)):
        raise ContactValidityError(
            f"contact state (rho, alpha, s_o) = {tuple(vals.tolist())} is not finite at s = {s:.6g}",
            s=s,
            condition="finite",
        )
    if rho <= 0.0:
        raise ContactValidityError(
            f"rho = {rho:.6g} at s = {s:.6g}: the contact distance must be > 0 "
            "(the arm centreline must stay outside the object)",
            s=s,
            condition="rho > 0",
        )
    if not 0.0 < alpha < np.pi:
        raise ContactValidityError(
            f"alpha = {alpha:.6g} at s = {s:.6g}: the contact angle must lie in (0, pi) "
            "(object on the left of the arm)",
            s=s,
            condition="0 < alpha < pi",
        )
    k_o = float(boundary.curvature(s_o))
    if 1.0 + rho * k_o <= 0.0:
        raise ContactValidityError(
            f"1 + rho kappa_o = {1.0 + rho * k_o:.6g} at s = {s:.6g} (rho = {rho:.6g}, "
            f"kappa_o = {k_o:.6g}): the shadow point would stop or run backwards "
            "(eq. (7) needs 1 + rho kappa_o > 0)",
            s=s,
            condition="1 + rho kappa_o > 0",
        )


_MAX_TURNING = 1e9  # largest |kappa| L integrate_contact accepts (radians of total turning)

KappaProfile = Callable[[float], float] | ArrayLike  # samples on s, or kappa(s) called at one s


def integrate_contact(
    s: ArrayLike,
    kappa: KappaProfile,
    boundary: Boundary,
    rho0: float,
    alpha0: float,
    s_o0: float,
    *,
    rtol: float = 1e-11,
    atol: float = 1e-12,
) -> ContactKinematics:
    """Integrate the contact kinematics (eqs. (7), (8)) along the arm.

    ``d rho/ds = -cos alpha``, ``d alpha/ds = -kappa + kappa_o sin(alpha) / (1 + rho kappa_o)``,
    ``d s_o/ds = nu_o = sin(alpha) / (1 + rho kappa_o)``, from (rho0, alpha0, s_o0) at ``s[0]``.
    ``kappa`` is either samples on ``s`` (interpolated by the same cubic spline as
    :func:`contgrasp_core.arm.shape_from_curvature`) or a callable of s. Integration uses
    DOP853 (8th order) at tolerance ``rtol``/``atol``; leaving the admissible region raises
    ContactValidityError naming the arclength where it happened.
    """
    ss = float_array("s", s)
    if ss.ndim != 1 or len(ss) < 2 or not np.all(np.isfinite(ss)) or np.any(np.diff(ss) <= 0.0):
        raise InvalidParameterError("s must be a finite, strictly increasing grid of >= 2 points")
    rtol = real("rtol", rtol, lo=100 * np.finfo(float).eps, hi=0.1)
    atol = real("atol", atol, lo=0.0)
    span = float(ss[-1] - ss[0])
    if not np.isfinite(span):
        raise InvalidParameterError("s spans more than the floating-point range")
    # |kappa| L beyond this would turn the arm 1e9 times: the integrator's error norms overflow
    # long before, and the contact would have left the admissible region within the first turn
    k_max = _MAX_TURNING / span
    if not callable(kappa):
        kk = float_array("kappa", kappa)
        if kk.shape == ss.shape and np.all(np.isfinite(kk)) and np.max(np.abs(kk)) > k_max:
            raise InvalidParameterError(
                f"|kappa| must be <= {_MAX_TURNING:.0e} / L = {k_max:.3g} (the arm would turn more than "
                f"{_MAX_TURNING:.0e} radians), got max |kappa| = {np.max(np.abs(kk)):.3g}"
            )
    kspline = kappa if callable(kappa) else curvature_spline(ss, kappa)
    check_state(boundary, rho0, alpha0, s_o0, s=float(ss[0]))

    def kfun(sv: float) -> float:
        try:
            k = float(kspline(sv))
        except (TypeError, ValueError) as exc:
            raise InvalidParameterError(f"kappa(s) at s = {sv:.6g} is not a number: {exc}") from exc
        if not abs(k) <= k_max:
            raise InvalidParameterError(f"kappa(s) = {k!r} at s = {sv:.6g}: must be finite with |kappa| <= {k_max:.3g}")
        return k

    def rhs(sv: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        rho, alpha, so = y
        k_o = float(boundary.curvature(so))
        nu = np.sin(alpha) / (1.0 + rho * k_o)
        return np.array([-np.cos(alpha), -kfun(sv) + k_o * nu, nu])

    def ev_rho(sv: float, y: NDArray[np.float64]) -> float:
        return y[0]

    def ev_alpha_lo(sv: float, y: NDArray[np.float64]) -> float:
        return y[1]

    def ev_alpha_hi(sv: float, y: NDArray[np.float64]) -> float:
        return np.pi - y[1]

    def ev_speed(sv: float, y: NDArray[np.float64]) -> float:
        return 1.0 + y[0] * float(boundary.curvature(y[2]))

    events = [ev_rho, ev_alpha_lo, ev_alpha_hi, ev_speed]
    for ev in events:
        # solve_ivp reads a `terminal` attribute of an event function; no callable type declares it
        ev.terminal = True  # type: ignore[attr-defined]
    from scipy.integrate import solve_ivp  # (here: the nodes never integrate; importing it costs them ~1 s)

    sol = solve_ivp(
        rhs,
        (ss[0], ss[-1]),
        np.array([rho0, alpha0, s_o0], dtype=float),
        method="DOP853",
        t_eval=ss,
        rtol=rtol,
        atol=atol,
        events=events,
    )
    names = ["rho > 0", "0 < alpha < pi", "0 < alpha < pi", "1 + rho kappa_o > 0"]
    assert sol.t_events is not None  # (set whenever events are given)
    for name, t_ev in zip(names, sol.t_events, strict=True):
        if len(t_ev):
            s_bad = float(t_ev[0])
            raise ContactValidityError(
                f"contact kinematics left the admissible region at s = {s_bad:.6g} "
                f"(of {ss[-1]:.6g}): {name} violated; choose a curvature profile that keeps "
                "the arm outside the object with the object on its left",
                s=s_bad,
                condition=name,
            )
    if sol.status != 0:  # the integrator gave up on an admissible state: a numerical failure, not bad input
        raise IntegrationError(f"contact kinematics integration failed at s = {float(sol.t[-1]):.6g}: {sol.message}")
    rho, alpha, s_o = sol.y
    return ContactKinematics(s=ss, rho=rho, alpha=alpha, s_o=s_o)


def shape_from_contact(
    s: ArrayLike, rho: ArrayLike, alpha: ArrayLike, s_o: ArrayLike, boundary: Boundary
) -> ArmShape:
    """Arm shape from the contact state (inverse of eq. (4)).

    ``r = gamma(s_o) - rho n(s_o)`` and ``theta = phi(s_o) + pi/2 - alpha``.
    """
    instance("boundary", boundary, Boundary)
    rr, aa, so, ss = (float_array(n, v) for n, v in (("rho", rho), ("alpha", alpha), ("s_o", s_o), ("s", s)))
    if not (rr.shape == aa.shape == so.shape == ss.shape):
        raise InvalidParameterError(
            f"s, rho, alpha, s_o must have equal shapes, got {ss.shape}, {rr.shape}, {aa.shape}, {so.shape}"
        )
    if not all(np.all(np.isfinite(v)) for v in (rr, aa, ss)) or np.any(np.abs(rr) > 1e150):
        raise InvalidParameterError("s, rho and alpha must be finite (|rho| <= 1e150)")
    phi = boundary.tangent_angle(so)
    normal = np.stack([-np.sin(phi), np.cos(phi)], axis=-1)
    r = boundary.point(so) - rr[..., None] * normal
    return ArmShape(s=ss, r=r, theta=phi + 0.5 * np.pi - aa)


def initial_state(boundary: Boundary, base: BasePose) -> tuple[float, float, float]:
    """(rho0, alpha0, s_o0) of an arm base pose, by closest-point projection.

    Raises ContactValidityError if the base is inside the object or the heading does not keep
    the object on the left (alpha0 outside (0, pi)).
    """
    instance("boundary", boundary, Boundary)
    instance("base", base, BasePose)
    proj = boundary.project(np.array([[base.x, base.y]]))
    rho0 = float(proj.signed_distance[0])
    s_o0 = float(proj.s_o[0])
    if rho0 <= 0.0:
        raise ContactValidityError(
            f"base pose ({base.x:.6g}, {base.y:.6g}) is inside the object or on its boundary "
            f"(signed distance {rho0:.6g}); place the base outside the object",
            s=0.0,
            condition="rho > 0",
        )
    alpha0 = float(_wrap_pi(boundary.tangent_angle(s_o0) + 0.5 * np.pi - base.theta))
    check_state(boundary, rho0, alpha0, s_o0)
    return rho0, alpha0, s_o0


def base_pose(boundary: Boundary, rho0: float, alpha0: float, s_o0: float) -> BasePose:
    """Base pose whose contact state is (rho0, alpha0, s_o0): ``r0 = gamma - rho0 n``."""
    check_state(boundary, rho0, alpha0, s_o0)
    shape = shape_from_contact([0.0], [rho0], [alpha0], [s_o0], boundary)
    return BasePose(float(shape.r[0, 0]), float(shape.r[0, 1]), float(shape.theta[0]))


def offset_curvature(
    boundary: Boundary, s: ArrayLike, distance: float, s_o0: float
) -> NDArray[np.float64]:
    """Curvature, in arm arclength, of the curve parallel to the boundary at ``distance``.

    An arm starting at ``(rho, alpha, s_o) = (distance, pi/2, s_o0)`` with this curvature
    keeps ``rho = distance`` and ``alpha = pi/2`` exactly (eq. (8) with
    ``d alpha/ds = 0``). With ``sigma`` the shadow arclength, the parallel curve has
    ``ds = (1 + d kappa_o(sigma)) d sigma`` so ``s = sigma - s_o0 + d (phi(sigma) - phi(s_o0))``
    and ``kappa = kappa_o / (1 + d kappa_o)``; for a circle of radius R this is 1/(R + d).
    """
    instance("boundary", boundary, Boundary)
    ss = float_array("s", s)
    if ss.size == 0 or not np.all(np.isfinite(ss)) or np.any(ss < 0.0):
        raise InvalidParameterError("s must be a non-empty array of finite arclengths >= 0")
    d = real("offset distance", distance, lo=0.0, lo_open=True)
    s_o0 = real("s_o0", s_o0)
    phi0 = float(boundary.tangent_angle(s_o0))

    def s_of_sigma(sig: NDArray[np.float64]) -> NDArray[np.float64]:
        return sig - s_o0 + d * (boundary.tangent_angle(sig) - phi0)

    span = float(np.max(ss)) + 1.0
    table = s_o0 + np.linspace(0.0, span, 4097)
    s_tab = s_of_sigma(table)
    k_tab = boundary.curvature(table)
    if np.any(1.0 + d * k_tab <= 0.0):
        raise ContactValidityError(
            f"no parallel curve at distance {d:.6g}: 1 + d kappa_o <= 0 on the boundary",
            s=0.0,
            condition="1 + rho kappa_o > 0",
        )
    sigma = np.interp(ss, s_tab, table)
    for _ in range(6):
        k_o = boundary.curvature(sigma)
        sigma = sigma - (s_of_sigma(sigma) - ss) / (1.0 + d * k_o)
    k_o = boundary.curvature(sigma)
    return k_o / (1.0 + d * k_o)
