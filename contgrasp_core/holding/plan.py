"""The planned hold, law ``hold`` (docs/holding.md, "A planned path of held shapes holds it").

Before the arm moves, the holding law (:class:`~contgrasp_core.control.hold_law.HoldController`)
runs on the object held fixed at its scenario pose, in the continuous loop at 2 ms
(:func:`~contgrasp_core.rod.closed_loop.run_closed_loop`, :data:`PLAN_LOOP`); the arm's joint
curvature at every step is the plan (:class:`HoldPlan`). :class:`PlannedHold` plays it back
from t = 0 as held shapes (H4) of stiffness G, with a damper (D, tau: a Maxwell element per
joint) on the arm's deviation from the plan from the planner's close on (P1), and keeps the
last shape once the plan ends, where, with friction, it squeezes (P2): the planned shape
shifted so that, at rest in it, the arm presses the object with the largest balanced set of
normal forces the penalty contact holds within ``plan_squeeze`` of the thinnest touching
element's radius (:func:`balanced_squeeze`). The command is linear in the state, so its
first-order hold is exact: the sampled loop runs it as the continuous one would.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.control.hold_law import HoldController, HoldLawSettings, ShapeHold
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod.closed_loop import ClosedLoopConfig
from contgrasp_core.rod.model import RodModel

if TYPE_CHECKING:
    from contgrasp_core.boundary import Boundary
    from contgrasp_core.scenario import Scenario

__all__ = ["PLAN_LOOP", "HoldPlan", "PlannedHold", "Squeeze", "balanced_forces", "balanced_squeeze", "plan_hold"]

Array = NDArray[np.float64]

PLAN_LOOP = ClosedLoopConfig(duration=20.0, dt=0.002, settle_speed=0.002, settle_hold=0.3, min_time=1.0,
                             max_iterations_per_period=40.0)
"""The plan's loop: continuous, steps of at most 2 ms (the graph's period: a coarser step damps
numerically, and with bounded muscles its Newton iterations halve the step down to ~0.1 ms),
stopped at settle (the paper scenario's criteria) within 20 s, refused once its rod engine needs
more than 40 Newton iterations per period on average (the set's circles' and ellipse's plans take
2.5; the kidney's, refused, 47 at its worst unbounded and more and more at 50 kPa, where it took
hours: docs/holding.md). Its own, not the run's:
a run shorter than the plan plays the plan's start, and the graph's controller plans as the core
does without the simulator's loop settings."""


@dataclass(frozen=True)
class Squeeze:
    """(P2) A balanced squeeze: the normal forces ``forces`` (n,) (N) on the object at the arm's
    touching ``elements`` (n,) and the joint couples ``couple`` (N,) (N m) they ask of the arm at
    rest (eqs. (17), (18): the moments of the forces beyond each joint)."""

    elements: NDArray[np.intp]
    forces: Array
    couple: Array

    @property
    def total(self) -> float:
        """The squeeze's total normal force (N)."""
        return float(self.forces.sum())


def balanced_forces(points: Array, normals: Array, caps: Array, a_ub: Array | None = None,
                    b_ub: Array | None = None) -> Array:
    """The largest total of normal forces ``0 <= f_j <= caps_j`` (n,) along the unit ``normals``
    (n, 2) at ``points`` (n, 2) with no net force and no net torque (a linear programme, scipy's
    HiGHS), and ``a_ub f <= b_ub`` if given; all zero when only zero balances (normals within a
    half-plane)."""
    from scipy.optimize import linprog

    torque = points[:, 0] * normals[:, 1] - points[:, 1] * normals[:, 0]
    res = linprog(-np.ones(len(caps)), A_ub=a_ub, b_ub=b_ub, A_eq=np.vstack([normals.T, torque]), b_eq=np.zeros(3),
                  bounds=list(zip(np.zeros(len(caps)), caps, strict=True)), method="highs")
    if res.status != 0 or res.x is None:
        raise InvalidParameterError(f"the balanced squeeze did not solve: {res.message}")
    return np.asarray(res.x, dtype=float)


def balanced_squeeze(rod: RodModel, boundary: Boundary, theta: Array, depth: float, tol: float) -> Squeeze:
    """(P2) The largest balanced squeeze of the rod at rest in the element angles ``theta`` on
    ``boundary``: normal forces at the elements whose surface is within ``tol`` (m) of the object,
    each at most what presses the penalty contact in by ``depth`` of the thinnest touching
    element's radius (``depth r_min h k``), with no net wrench on the object; with bounded
    muscles, each joint's squeeze couple within half the headroom between the bound and the
    shape's own couple (none where the shape alone asks for the bound)."""
    from contgrasp_core.holding.ceiling import moment_columns
    from contgrasp_core.rod import chain

    proj = boundary.project(chain.centres(rod, theta))
    touching = np.flatnonzero(proj.signed_distance - rod.r_centres <= tol)
    inward = -proj.normal_out[touching]
    cols = moment_columns(rod, theta, touching, -inward)  # (the object pushes back on the arm)
    a_ub = b_ub = None
    if rod.muscle_bound is not None:  # (the squeeze's couple within half the muscles' headroom over the shape's)
        room = 0.5 * np.maximum(rod.muscle_bound - np.abs(rod.joint_ei * rod.joint_curvature(theta)), 0.0)
        a_ub, b_ub = np.vstack([cols, -cols]), np.concatenate([room, room])
    caps = np.full(len(touching), depth * rod.r_centres[touching].min(initial=np.inf) * rod.h * rod.contact_stiffness)
    forces = balanced_forces(proj.foot[touching], inward, caps, a_ub, b_ub) if len(touching) else np.zeros(0)
    return Squeeze(touching, forces, cols @ forces)


@dataclass(frozen=True)
class HoldPlan:
    """A path of held shapes: the times ``t`` (s, increasing from 0) and the joint curvature
    ``kappa`` (len(t), N) at each (1/m); ``close`` (s) when the planner's cage closed (H2): from
    then on the arm is near the object and the playback damps its deviation; ``squeeze`` the
    balanced squeeze (P2) at the plan's last shape (None: none, as without friction)."""

    t: Array
    kappa: Array
    close: float
    squeeze: Squeeze | None = None

    def __post_init__(self) -> None:
        t, k = np.asarray(self.t, dtype=float), np.asarray(self.kappa, dtype=float)
        if t.ndim != 1 or t.size < 1 or k.ndim != 2 or k.shape[0] != t.size:
            raise InvalidParameterError(f"a plan needs times (n,) and curvatures (n, N), got {t.shape} and {k.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(k)) and np.all(np.diff(t) > 0)):
            raise InvalidParameterError("a plan's times must increase and its curvatures be finite")
        if not (np.isfinite(self.close) and t[0] <= self.close <= t[-1]):
            raise InvalidParameterError(f"a plan's close must be within its times, got {self.close!r}")
        if self.squeeze is not None and (self.squeeze.couple.shape != k.shape[1:] or not np.all(np.isfinite(self.squeeze.couple))):
            raise InvalidParameterError(f"a plan's squeeze needs {k.shape[1]} finite joint couples")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "kappa", k)

    @property
    def end(self) -> float:
        """The plan's last time (s)."""
        return float(self.t[-1])

    def at(self, t: float) -> Array:
        """The planned curvature at ``t`` (s): linear in the recorded times, joint by joint; the
        first shape before the start and the last after the end."""
        times = self.t
        if t <= times[0]:
            return self.kappa[0].copy()
        if t >= times[-1]:
            return self.kappa[-1].copy()
        i = int(np.searchsorted(times, t, side="right"))  # (times[i - 1] <= t < times[i])
        w = (t - times[i - 1]) / (times[i] - times[i - 1])
        return np.asarray((1.0 - w) * self.kappa[i - 1] + w * self.kappa[i], dtype=np.float64)


def plan_hold(scenario: Scenario) -> HoldPlan:
    """The plan of ``scenario``: its holding law (its rod, gains and hold settings) on its object
    held fixed at its pose, in :data:`PLAN_LOOP`, and with friction its squeeze (P2; without,
    normal forces resist no slip and, measured, a squeeze turns a frictionless ellipse away).
    :class:`InvalidParameterError` when the run never reaches the hold (the plan would not hold
    anything)."""
    from contgrasp_core.rod import chain
    from contgrasp_core.rod.body import ObjectDynamics
    from contgrasp_core.rod.closed_loop import run_closed_loop
    from contgrasp_core.rod.integrator import StepFailedError

    loop = PLAN_LOOP
    planner = replace(scenario, law="reactive", dynamics=ObjectDynamics(), disturbance=None, loop=loop)
    law = planner.controller()
    assert isinstance(law, HoldController)
    system = planner.system()
    try:
        res = run_closed_loop(system, planner.feedback_gains, loop, law=law)
    except StepFailedError as e:
        raise InvalidParameterError(f"the planned hold has no plan: the holding law on the fixed {scenario.object.text()} "
                                    f"could not be computed ({e})") from None
    if not law.holding or law.closed_at is None:
        raise InvalidParameterError(
            f"the planned hold has no plan: the holding law on the fixed {scenario.object.text()} did not reach its "
            f"hold within {loop.duration:g} s (phase {getattr(law, 'phase', '?')}; a longer duration or another pose)")
    m = scenario.rod
    kappa = np.array([m.joint_curvature(chain.element_angles(theta)) for theta in res.theta])
    depth = scenario.hold_law.plan_squeeze if m.friction > 0 else 0.0  # (P2: friction is what a squeeze serves)
    assert system.obstacle is not None
    squeeze = None if depth == 0 else balanced_squeeze(m, system.obstacle.boundary, res.final_state.theta, depth,
                                                       scenario.sensing.contact_tolerance)
    return HoldPlan(np.asarray(res.t, dtype=float), kappa, law.closed_at, squeeze)


class PlannedHold:
    """The playback of a :class:`HoldPlan` (module docstring; docs/holding.md (P1)): ``phase``
    ``plan`` until the plan's end, then ``hold`` (``holding``); :meth:`command` gives the held
    shape at the law's own time and advances it by the period."""

    name: ClassVar[str] = "hold"

    def __init__(self, model: RodModel, plan: HoldPlan, settings: HoldLawSettings) -> None:
        if plan.kappa.shape[1] != model.n_elements:
            raise InvalidParameterError(f"the plan has {plan.kappa.shape[1]} joints; the rod has {model.n_elements}")
        self.model, self.plan = model, plan
        self.gain, self.damping, self.damping_time = settings.plan_gain, settings.plan_damping, settings.plan_damping_time
        self.squeeze_time = settings.plan_squeeze_time
        self.t = 0.0
        self.xi = np.zeros(model.n_elements)  # (the dampers' own strain, 1/m: relaxed, = the deviation, until the close)

    @classmethod
    def from_scenario(cls, scenario: Scenario, plan: HoldPlan | None = None) -> PlannedHold:
        """A fresh playback of ``scenario``'s plan (computed by :func:`plan_hold` unless given)
        with its hold settings."""
        return cls(scenario.rod, plan_hold(scenario) if plan is None else plan, scenario.hold_law)

    @property
    def holding(self) -> bool:
        """The plan's end is reached: its last shape is held."""
        return self.t >= self.plan.end

    @property
    def phase(self) -> str:
        """``plan`` while the path plays, ``hold`` after."""
        return "hold" if self.holding else "plan"

    def command(self, rho: Array, alpha: Array, theta: Array, kappa: Array, period: float) -> ShapeHold:
        """(P1) at the law's time from the sensed curvature ``kappa`` (what else is sensed is not
        used: the plan is the reference), then the dampers relax over ``period`` (s) and the time
        advances: ``u = -EI kp + G EI e + D EI (e - xi)``, ``e = kappa - kp``, the held shape
        ``ShapeHold(kp + D xi / (1 + G + D), G + D)``; after the plan's end (P2) ``kp`` is the last
        shape less ``C / ((1 + G) EI)``, the squeeze's couple ``C`` ramped in over
        ``plan_squeeze_time`` (at rest in the planned shape the arm then carries ``C``)."""
        kp = self.plan.at(self.t)
        sq = self.plan.squeeze
        if sq is not None and self.t > self.plan.end:
            ramp = min(1.0, (self.t - self.plan.end) / self.squeeze_time)
            kp = kp - ramp * sq.couple / ((1.0 + self.gain) * self.model.joint_ei)
        e = np.asarray(kappa, dtype=float) - kp
        d = self.damping if self.t >= self.plan.close else 0.0
        out = ShapeHold(self.model, kp + d * self.xi / (1.0 + self.gain + d), self.gain + d)
        if d > 0:
            self.xi += -np.expm1(-period / self.damping_time) * (e - self.xi)
        else:
            self.xi = e
        self.t += period
        return out
