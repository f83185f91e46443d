"""What a grasp resists (beyond the paper): the stiffness and the holding capacity of a settled grasp.

The paper rates a grasp by its Gramian's eigenvalues (Sec. IV, Q1-Q3) and never loads the
object. :func:`measure_holding` loads it on the rod engine (the object a rigid body,
:mod:`contgrasp_core.rod.body`; stick-slip friction, :mod:`contgrasp_core.rod.coupling`), the
feedback law running throughout: 1. grasp the fixed object until settled (Q1-Q3, and
:func:`force_weighted_quality`); 2. release it onto a soft support (``support = 0``: free) and
see whether it stays held; 3. the stiffness ``K`` from wrench steps of ``+-probe``; 4. the
holding capacity per direction of a rising wrench, up to escape. A grasp that does not settle is
a :class:`GraspFailure`; one that does not hold is a result. docs/holding.md, "What is measured".
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.boundary import Boundary
from contgrasp_core.contact import ContactState, sense
from contgrasp_core.control.hold_law import HOLDING_LAWS
from contgrasp_core.errors import InvalidParameterError, RunFailure
from contgrasp_core.holding.ceiling import MuscleCeiling, muscle_ceiling
from contgrasp_core.holding.plan import PlannedHold
from contgrasp_core.quality import GraspQuality, quality_of_state
from contgrasp_core.rod.body import BodyState, ObjectDynamics, mass_properties
from contgrasp_core.rod.integrator import RodState
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.session import LoopSession, Observation, drive, run_sampled, sensed_shape
from contgrasp_core.scenario import Scenario

__all__ = ["HoldSettings", "Capacity", "HoldResult", "HoldExperiment", "GraspFailure", "measure_holding",
           "wrench_directions", "force_weighted_quality"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class HoldSettings:
    """How :func:`measure_holding` loads a grasp (SI; module docstring): the released object's
    ``areal_density`` (kg/m^2) and ``support`` stiffness (N/m; the rotation's is ``support a^2``
    N m/rad, ``a`` the object's nominal radius) with damping ratio ``support_damping_ratio``;
    friction coefficient ``mu`` (stick-slip), the ``release_time``, the stiffness ``probe``
    wrench (fx, fy, torque) and ``hold_time``, the capacity ramp's ``rate`` (N/s in the scaled
    wrench space) and ``ramp_time``, the number of force ``directions`` (plus the two pure
    torques), the escape thresholds (``escape_distance`` in object radii), and how long the
    grasp may go without touching the object (``contact_wait``, s, from the start or a planned
    hold's close; the holding law's cage counts as touching within its clearance and band)
    before it counts as failed. ``support = 0`` releases the object entirely free."""

    areal_density: float = 10.0
    support: float = 2.0
    support_damping_ratio: float = 1.0
    mu: float = 0.5
    release_time: float = 0.5
    probe: tuple[float, float, float] = (2e-3, 2e-3, 5e-5)
    hold_time: float = 1.0
    rate: float = 0.05
    ramp_time: float = 2.0
    directions: int = 8
    escape_distance: float = 0.5
    escape_angle: float = 0.5
    contact_wait: float = 0.6

    def dynamics(self, scale: float, area: float, polar: float) -> ObjectDynamics:
        """The released object on the support spring-damper (``scale`` the object's radius, m;
        ``area`` and ``polar`` moment of its region, m^2 and m^4, for mass, inertia and the
        damping ratio); entirely free when ``support`` is 0."""
        if self.support == 0:
            return ObjectDynamics(mode="free", areal_density=self.areal_density)
        k = np.array([self.support, self.support, self.support * scale**2])
        inertia = self.areal_density * np.array([area, area, polar])
        c = 2.0 * self.support_damping_ratio * np.sqrt(k * inertia)
        return ObjectDynamics(mode="spring", areal_density=self.areal_density, stiffness=tuple(k), damping=tuple(c))

    def __post_init__(self) -> None:
        for name in ("areal_density", "support", "support_damping_ratio", "mu", "release_time", "hold_time", "rate",
                     "ramp_time", "escape_distance", "escape_angle", "contact_wait"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and (v >= 0 if name == "support" else v > 0)):
                raise InvalidParameterError(f"hold {name} must be a finite number {'>=' if name == 'support' else '>'} 0, "
                                            f"got {v!r}")
        p = np.asarray(self.probe, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or np.any(p <= 0):
            raise InvalidParameterError(f"hold probe must be three finite numbers > 0 (fx, fy, torque), got {self.probe!r}")
        if int(self.directions) != self.directions or self.directions < 1:
            raise InvalidParameterError(f"hold directions must be an integer >= 1, got {self.directions!r}")


@dataclass(frozen=True)
class Capacity:
    """The ramp along ``direction`` (unit, scaled wrench space): the ``wrench`` (fx, fy, torque)
    and its scaled magnitude ``magnitude`` (N) when the object escaped (``held`` False, with the
    ``reason``) or when the ramp ended with the object still held (``held`` True)."""

    direction: tuple[float, float, float]
    wrench: tuple[float, float, float]
    magnitude: float
    held: bool
    reason: str


@dataclass(frozen=True)
class HoldResult:
    """A grasp's measured holding (module docstring): ``held`` whether the released object stayed
    (``release_reason`` why not, '' if it did; then ``stiffness`` and ``stiffness_eigenvalues``
    are None and every capacity is 0); ``grasp`` the grasp's validity and the muscles' effort
    (:meth:`~contgrasp_core.rod.validity.RunHealth.validity` and ``effort``)."""

    stiffness: Array | None
    support: Array
    stiffness_eigenvalues: Array | None
    capacity: list[Capacity]
    Q1: float
    Q2: float
    Q3: float
    force_weighted: GraspQuality
    scale: float
    released_displacement: Array
    settle_time: float | None
    held: bool = True
    release_reason: str = ""
    pressure_max: float = float("nan")
    friction_bound: tuple[float, ...] = ()
    grasp: dict[str, Any] = field(default_factory=dict)
    ceiling: MuscleCeiling | None = None

    @property
    def capacity_min(self) -> float:
        """The worst direction's capacity (N, scaled wrench space)."""
        return min(c.magnitude for c in self.capacity)

    @property
    def weakest(self) -> Capacity:
        """The direction of :attr:`capacity_min` (the first of equals)."""
        return min(self.capacity, key=lambda c: c.magnitude)

    @property
    def capacity_is_bound(self) -> bool:
        """:attr:`capacity_min` is only a lower bound: its direction held to the ramp's end (the
        object never escaped there), so the grasp may hold more."""
        return self.weakest.held

    def to_dict(self) -> dict[str, Any]:
        """The JSON-able result (``contgrasp hold --json``)."""
        return {
            "held": self.held,
            "release_reason": self.release_reason,
            "stiffness": None if self.stiffness is None else self.stiffness.tolist(),
            "support_stiffness": self.support.tolist(),
            "stiffness_eigenvalues": None if self.stiffness_eigenvalues is None else self.stiffness_eigenvalues.tolist(),
            "capacity": [{"direction": list(c.direction), "wrench": list(c.wrench), "magnitude": c.magnitude,
                          "held": c.held, "reason": c.reason, "friction_bound": bound,
                          "bound_ratio": c.magnitude / bound if bound > 0 else None, "muscle_ceiling": _finite(top)}
                         for c, bound, top in zip(self.capacity,
                                                  self.friction_bound or [float("nan")] * len(self.capacity),
                                                  [float("nan")] * len(self.capacity) if self.ceiling is None
                                                  else self.ceiling.capacity, strict=True)],
            "pressure_max": self.pressure_max,
            "capacity_min": self.capacity_min,
            "capacity_is_bound": self.capacity_is_bound,
            "capacity_min_reason": self.weakest.reason,
            "muscle_ceiling_min": None if self.ceiling is None else _finite(float(self.ceiling.capacity.min())),
            "muscles_hold_shape": None if self.ceiling is None else self.ceiling.holds_shape,
            "Q1": self.Q1, "Q2": self.Q2, "Q3": self.Q3,
            "Q1_force": self.force_weighted.Q1, "Q2_force": self.force_weighted.Q2, "Q3_force": self.force_weighted.Q3,
            "scale_m": self.scale,
            "released_displacement": self.released_displacement.tolist(),
            "settle_time_s": self.settle_time,
            **self.grasp,
        }


def _finite(value: float) -> float | None:
    """``value`` for JSON: None for no ceiling (unbounded muscles, ``inf``)."""
    return None if np.isinf(value) else float(value)


def _penetration(rod: RodModel, boundary: Boundary, theta: Array) -> tuple[Any, Array]:
    """The projection of the rod's element centres in ``theta`` onto ``boundary`` and the depth
    of the rod surface inside it there, ``max(r - distance, 0)`` (m): where the penalty contact acts."""
    from contgrasp_core.rod import chain

    proj = boundary.project(chain.centres(rod, theta))
    return proj, np.maximum(rod.r_centres - proj.signed_distance, 0.0)


def force_weighted_quality(scenario: Scenario, theta: Array) -> GraspQuality:
    """Q1-Q3 of ``W_f = sum_i f_i G_i G_i^T``: the point grasp maps (paper Sec. IV-A) at the
    feet of the rod's element centres, weighted by their penalty contact forces ``f_i = h k
    max(pen_i, 0)`` (N) instead of arclength (the rod at rest on the fixed object)."""
    from contgrasp_core.quality import metrics_from_gramian, weighted_gramian

    m = scenario.rod
    proj, pen = _penetration(m, scenario.object.boundary(), theta)
    force = m.h * m.contact_stiffness * pen
    w = weighted_gramian(proj.foot, proj.phi, force, scenario.reference)
    return metrics_from_gramian(w, float(m.h * np.count_nonzero(force)))


def friction_bound(rod: RodModel, boundary: Boundary, theta: Array, mu: float, directions: Array,
                   ref: tuple[float, float], scale: float) -> tuple[float, Array]:
    """The friction bound of the rod at rest in ``theta`` on the object's ``boundary``
    (docs/holding.md, (M2)): the largest line pressure ``p_max = k max(pen, 0)`` (N/m) at the
    rod's element centres and ``p_max h(d)`` (N) for each row of ``directions`` (scaled wrench
    space: torque about ``ref`` over ``scale``): what the contact could resist along ``d`` with
    its pressure nowhere above today's largest and Coulomb ``mu`` (the role the capstan law
    plays for a belt)."""
    from contgrasp_core.holding.measure import support, wrench_generators

    proj, pen = _penetration(rod, boundary, theta)
    p_max = float(rod.contact_stiffness * pen.max())
    gen = wrench_generators(proj.foot, proj.phi, mu, ref, scale)
    return p_max, p_max * support(gen, np.where(pen > 0, rod.h, 0.0), directions)


def wrench_directions(n_force: int) -> Array:
    """Unit directions in the scaled wrench space: ``n_force`` force directions evenly around
    the circle, then the pure torques +1 and -1 (rows, (n_force + 2, 3))."""
    ang = 2.0 * np.pi * np.arange(n_force) / n_force
    forces = np.stack([np.cos(ang), np.sin(ang), np.zeros(n_force)], axis=1)
    return np.vstack([forces, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])


def _escape(obs: Observation, contact: ContactState, q0: Array, settings: HoldSettings) -> str:
    """Why the object counts as escaped at ``obs`` with its sensed ``contact`` ('' while held)."""
    assert obs.body is not None
    dq = obs.body.q - q0
    if np.hypot(dq[0], dq[1]) > settings.escape_distance:
        return "moved"
    if abs(dq[2]) > settings.escape_angle:
        return "turned"
    if not contact.in_contact.any():
        return "contact lost"
    return ""


class GraspFailure(RunFailure):
    """The closed loop made no settled grasp to measure; ``outcome`` says how (``no contact`` or
    ``not settled``, :meth:`HoldExperiment.grasp`)."""

    def __init__(self, outcome: str, message: str) -> None:
        super().__init__(message)
        self.outcome = outcome


class HoldExperiment:
    """One grasp loaded step by step (module docstring): :meth:`grasp`, :meth:`release`, then any
    number of :meth:`load` runs from the released state (:meth:`stiffness`, :meth:`capacity`)."""

    def __init__(self, scenario: Scenario, settings: HoldSettings = HoldSettings()) -> None:
        if scenario.dynamics.mode != "fixed":
            raise InvalidParameterError("the grasp is made with the object fixed; give a scenario with a fixed object")
        self.scenario, self.settings = scenario, settings
        self.boundary = scenario.object.boundary()
        self.scale = float(scenario.object.radius)
        area, _, polar = mass_properties(self.boundary)
        self.dynamics = settings.dynamics(self.scale, area, polar)
        self.held = replace(scenario, rod=replace(scenario.rod, friction=settings.mu, friction_model="stick"),
                            dynamics=self.dynamics)
        self.system = self.held.system()
        self.escape = replace(settings, escape_distance=settings.escape_distance * self.scale)
        self.law = self.held.controller()  # (planned, law hold, with the friction it grasps with)
        h = scenario.hold_law
        self.reach = max(scenario.sensing.contact_tolerance, h.clearance + h.band if scenario.law in HOLDING_LAWS else 0.0)
        self.grasped: LoopSession | None = None
        self.released: RodState | None = None
        self.release_reason = ""

    def grasp(self) -> tuple[GraspQuality, GraspQuality]:
        """The scenario's closed loop with the object fixed, until settled; Q1-Q3 of its contact,
        and the force-weighted variant (:func:`force_weighted_quality`). :class:`GraspFailure`
        if it does not settle (module docstring)."""
        tol, wait = self.scenario.sensing.contact_tolerance, self.settings.contact_wait
        # when a node last touched the object: the start counts as a touch, and so does a planned
        # hold's close (its plan says when its arm reaches the object: 0.62 s at 50 kPa)
        touched = [self.law.plan.close if isinstance(self.law, PlannedHold) else 0.0]

        def out_of_reach(o: Observation, c: ContactState) -> bool:
            if (c.delta >= -self.reach).any():
                touched[0] = o.t
            return o.t - touched[0] >= wait

        grasp = run_sampled(self.scenario, until=out_of_reach, law=self.law)
        obs = grasp.observe()
        contact = sense(obs.shape, self.boundary, obs.radius, tol=tol)
        if not grasp.settled:
            if not contact.in_contact.any():
                raise GraspFailure("no contact", f"no node touched the object for {wait:g} s (at t = {obs.t:.3g} s, "
                                   f"the arm moving at up to {obs.max_speed:.3g} m/s); no holding to measure (an arm "
                                   "still on its way, slowed by bounded muscles say, needs a longer contact_wait)")
            if not grasp.health.valid:
                raise GraspFailure("invalid", f"the grasp left the model's validity: {'; '.join(grasp.health.broken())}; "
                                   "no holding to measure")
            raise GraspFailure("not settled", f"the grasp did not settle within {self.scenario.loop.duration:g} s (still "
                               f"moving at up to {obs.max_speed:.3g} m/s, {int(contact.in_contact.sum())} nodes in "
                               "contact); no holding to measure")
        self.grasped = grasp
        return (quality_of_state(contact, self.boundary, ref=self.scenario.reference),
                force_weighted_quality(self.scenario, grasp.state.theta))

    def release(self) -> Array:
        """Release the grasped object onto its support; its displacement at the end of the
        release (3,). ``release_reason`` says why the grasp does not hold it ('' if it does: the
        object has not escaped, :func:`_escape`)."""
        if self.grasped is None:
            self.grasp()
        assert self.grasped is not None
        st = self.grasped.state
        released, last, failed = self.load(RodState(0.0, st.theta, st.omega, body=BodyState.rest()),
                                           self.settings.release_time, lambda t: np.zeros(3))
        assert released.body is not None  # (the released object is a body)
        contact = sense(sensed_shape(self.system, last), self.boundary, last.radius,
                        tol=self.scenario.sensing.contact_tolerance)
        self.release_reason = failed or _escape(last, contact, np.zeros(3), self.escape)
        self.released = released
        return released.body.q

    def _from_release(self) -> RodState:
        if self.released is None:
            self.release()
        assert self.released is not None
        if self.release_reason:
            raise RunFailure(f"the released object is not held ({self.release_reason}): nothing to load")
        return self.released

    def load(self, state: RodState, duration: float, wrench: Callable[[float], Array],
             until: Callable[[Observation, ContactState], bool] | None = None) -> tuple[RodState, Observation, str]:
        """The closed loop from ``state`` (time reset to 0) with ``wrench(t)`` on the object, for
        ``duration`` or until ``until(observation, contact)``: the final state and observation, and why
        the simulation failed ('' if it did not: a tear-out that breaks the run is a result)."""
        loop = replace(self.held.loop, duration=duration, min_time=duration + 1.0)  # (never "settled")
        session = LoopSession(self.system, loop, replace(state, t=0.0))
        try:  # (each load goes on from the grasp's law: a copy of its state at the end of the grasp)
            last = drive(session, self.held, wrench, until, copy.deepcopy(self.law))
        except RunFailure as exc:
            return session.state, session.observe(), f"simulation failed ({exc})"
        return session.state, last, ""

    def displacement_under(self, wrench: Array, duration: float | None = None) -> Array:
        """The object's displacement from its released pose under a constant ``wrench`` held
        for ``duration`` (default ``hold_time``)."""
        start = self._from_release()
        st, _, failed = self.load(start, self.settings.hold_time if duration is None else duration,
                                  lambda t: np.asarray(wrench, dtype=float))
        if failed or st.body is None or start.body is None:
            raise RunFailure(f"the grasp gave way under the wrench {np.asarray(wrench).tolist()}: {failed}")
        return st.body.q - start.body.q

    def stiffness(self) -> tuple[Array, Array]:
        """The grasp's own stiffness ``K = C^-1 - K_support`` from the ``+-probe`` steps, and the
        compliance ``C`` (grasp and support together)."""
        compliance = np.empty((3, 3))
        for j in range(3):
            w = np.zeros(3)
            w[j] = self.settings.probe[j]
            compliance[:, j] = (self.displacement_under(w) - self.displacement_under(-w)) / (2.0 * w[j])
        grasp = np.asarray(np.linalg.inv(compliance) - np.diag(self.dynamics.stiffness), dtype=np.float64)
        return grasp, compliance

    def capacity(self, direction: Array) -> Capacity:
        """The ramp along ``direction`` (unit, scaled wrench space) until the object escapes."""
        start = self._from_release()
        assert start.body is not None
        q0 = start.body.q
        unscaled = np.asarray(direction, dtype=float) * np.array([1.0, 1.0, self.scale])
        rate = self.settings.rate
        reason = [""]

        def escaped(o: Observation, c: ContactState) -> bool:
            reason[0] = _escape(o, c, q0, self.escape)
            return bool(reason[0])

        _, last, failed = self.load(start, self.settings.ramp_time, lambda t: rate * t * unscaled, escaped)
        why = failed or reason[0]
        magnitude = rate * last.t
        return Capacity(direction=tuple(float(x) for x in direction),  # type: ignore[arg-type]
                        wrench=tuple(float(x) for x in magnitude * unscaled),  # type: ignore[arg-type]
                        magnitude=float(magnitude), held=not why,
                        reason=why or f"held to the ramp's end at {magnitude:.4g} N: a lower bound (a longer --ramp-time reaches further)")


def measure_holding(scenario: Scenario, settings: HoldSettings = HoldSettings(),
                    progress: Callable[[str], None] | None = None) -> HoldResult:
    """Grasp, release, probe and ramp (module docstring). ``progress`` is told each phase."""
    say = progress or (lambda _: None)
    exp = HoldExperiment(scenario, settings)
    say("grasp")
    quality, forced = exp.grasp()
    say("release")
    q0 = exp.release()
    assert exp.grasped is not None
    p_max, bound = friction_bound(scenario.rod, exp.boundary, exp.grasped.state.theta, settings.mu,
                                  wrench_directions(settings.directions), scenario.reference, exp.scale)
    bounds = tuple(float(b) for b in bound)
    ceiling = muscle_ceiling(scenario.rod, exp.boundary, exp.grasped.state.theta, mu=settings.mu,
                             directions=wrench_directions(settings.directions), ref=scenario.reference,
                             scale=exp.scale, tol=scenario.sensing.contact_tolerance)
    health = {"validity": exp.grasped.health.validity(), **exp.grasped.health.effort()}
    if exp.release_reason:
        return HoldResult(stiffness=None, support=np.diag(exp.dynamics.stiffness), stiffness_eigenvalues=None,
                          capacity=[Capacity(direction=tuple(float(x) for x in d),  # type: ignore[arg-type]
                                             wrench=(0.0, 0.0, 0.0), magnitude=0.0, held=False,
                                             reason=f"not held after the release ({exp.release_reason})")
                                    for d in wrench_directions(settings.directions)],
                          Q1=quality.Q1, Q2=quality.Q2, Q3=quality.Q3, force_weighted=forced, scale=exp.scale,
                          released_displacement=q0, settle_time=exp.grasped.settle_time, held=False,
                          release_reason=exp.release_reason, pressure_max=p_max, friction_bound=bounds, grasp=health,
                          ceiling=ceiling)
    say("stiffness")
    stiffness, _ = exp.stiffness()
    d = np.diag([1.0, 1.0, 1.0 / exp.scale])
    scaled = d @ stiffness @ d
    eig = np.asarray(np.linalg.eigvalsh(0.5 * (scaled + scaled.T)), dtype=float)
    capacity = []
    for direction in wrench_directions(settings.directions):
        say(f"capacity along {np.round(direction, 3).tolist()}")
        capacity.append(exp.capacity(direction))
    return HoldResult(stiffness=stiffness, support=np.diag(exp.dynamics.stiffness), stiffness_eigenvalues=eig,
                      capacity=capacity, Q1=quality.Q1, Q2=quality.Q2, Q3=quality.Q3, force_weighted=forced,
                      scale=exp.scale,
                      released_displacement=q0, settle_time=exp.grasped.settle_time,
                      pressure_max=p_max, friction_bound=bounds, grasp=health, ceiling=ceiling)
