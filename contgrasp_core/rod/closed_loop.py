"""Closed-loop grasp: the rod engine driven by the feedback law (paper Sec. V-B, V-C).

``control_period=None`` (default): continuous feedback, the law inside every implicit step
(:class:`~contgrasp_core.control.StateFeedback`, the loop of Prop. 5.2). ``control_period=T``:
the couple of eq. (19) sensed every ``T`` and held (zero-order), as a lock-step ROS loop without
the first-order hold; it flutters unless ``T`` is well below the tip's bending periods. The
runner records every ``record_period`` and stops at ``duration`` or, against a fixed object, once
settled (:class:`SettleDetector`; a movable object is watched to the end: :func:`stops_at_settle`).
:func:`static_solution` is Fig. 4's static closed loop (eq. (8) with eq. (20)) of a run's result.
docs/rod.md, "Closing the loop".
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from contgrasp_core.contact import sense
from contgrasp_core.control.gains import FeedbackGains
from contgrasp_core.control.law import closed_loop_kinematics, feedback_couple
from contgrasp_core.control.rod_feedback import StateFeedback
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import chain
from contgrasp_core.rod.body import to_world
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.muscle import saturate
from contgrasp_core.rod.validity import RunHealth

if TYPE_CHECKING:  # (imported by the runner: the scenario's ClosedLoopConfig comes without the engine)
    from contgrasp_core.control.hold_law import Law
    from contgrasp_core.rod.integrator import RodState, RodSystem
    from contgrasp_core.rod.obstacle import Obstacle

__all__ = ["MIN_CONTROL_PERIOD", "ClosedLoopConfig", "ClosedLoopResult", "SettleDetector", "stops_at_settle", "run_closed_loop", "object_motion",
           "static_solution"]


MIN_CONTROL_PERIOD = 1e-4
"""The shortest control period, s (10 kHz; the graph's is 2 ms, the tests' shortest 0.5 ms): the
rod takes at least one implicit step per period, so a shorter one only multiplies the steps
(``simulate --control-period 1e-9`` ran practically forever). The CLI and the nodes' parameter share it."""


@dataclass(frozen=True)
class ClosedLoopConfig:
    """Run settings (s, m/s): ``duration``; ``control_period`` (None = continuous feedback);
    integrator step ``dt`` (with a control period it must divide it; None = the control period,
    or 0.01 s for continuous feedback); ``record_period`` (None = every control update / step);
    ``settle_speed``, ``settle_hold``, ``min_time``; ``max_iterations_per_period`` (None: no
    limit): from the 100th period on, a run whose rod engine has taken more Newton iterations
    than this per period on average stops with
    :class:`~contgrasp_core.rod.integrator.StepFailedError` (its steps fail and shrink, e.g. with
    the arm touching itself under bounded muscles, and it would take hours)."""

    duration: float = 20.0
    control_period: float | None = None
    dt: float | None = None
    record_period: float | None = None
    settle_speed: float = 2e-4
    settle_hold: float = 0.5
    min_time: float = 1.0
    max_iterations_per_period: float | None = None

    def __post_init__(self) -> None:
        for name in ("duration", "settle_speed", "settle_hold", "control_period", "dt", "record_period"):
            v = getattr(self, name)
            if v is None and name in ("control_period", "dt", "record_period"):
                continue
            if not (np.isfinite(v) and v > 0):
                raise InvalidParameterError(f"{name} must be finite and > 0, got {v!r}")
        if self.control_period is not None and self.control_period < MIN_CONTROL_PERIOD:
            raise InvalidParameterError(f"control_period must be at least {MIN_CONTROL_PERIOD:g} s (one implicit rod step "
                                        f"per period at least), got {self.control_period!r}")
        if not (np.isfinite(self.min_time) and self.min_time >= 0):
            raise InvalidParameterError("min_time must be finite and >= 0")
        if self.max_iterations_per_period is not None and not (np.isfinite(self.max_iterations_per_period)
                                                               and self.max_iterations_per_period >= 1):
            raise InvalidParameterError(f"max_iterations_per_period must be finite and >= 1, got {self.max_iterations_per_period!r}")
        if self.control_period is not None and self.dt is not None:
            n = self.control_period / self.dt
            if abs(n - round(n)) > 1e-9 or round(n) < 1:
                raise InvalidParameterError(
                    f"dt={self.dt!r} must divide control_period={self.control_period!r}")

    @property
    def period(self) -> float:
        """Interval between control updates (sampled) or between recorded integrator steps."""
        if self.control_period is not None:
            return self.control_period
        return 0.01 if self.dt is None else self.dt

    @property
    def substeps(self) -> int:
        if self.control_period is None or self.dt is None:
            return 1
        return int(round(self.control_period / self.dt))


@dataclass
class SettleDetector:
    """Settled: every node slower than ``settle_speed`` for the last ``settle_hold`` seconds, not
    before ``min_time``. Fed the observed states in time order (the closed loop, or a recording),
    it judges the latest: a rod that moves again is no longer settled, and ``settle_time`` is the
    start of the quiet stretch it is in."""

    settle_speed: float
    settle_hold: float
    min_time: float
    quiet_since: float | None = None
    settled: bool = False

    def update(self, t: float, max_speed: float, ready: bool = True) -> bool:
        """Account for the state at time ``t`` with the given largest node speed; returns settled.
        A state that is not ``ready`` (a law still in transition) does not count as quiet."""
        if ready and max_speed < self.settle_speed:
            self.quiet_since = t if self.quiet_since is None else self.quiet_since
            self.settled = t >= self.min_time and t - self.quiet_since >= self.settle_hold
        else:
            self.quiet_since = None
            self.settled = False
        return self.settled

    @property
    def settle_time(self) -> float | None:
        return self.quiet_since if self.settled else None


def stops_at_settle(system: RodSystem) -> bool:
    """Whether a closed loop on ``system`` ends once settled: against a fixed object (the
    paper's runs), yes; a movable object is watched until the duration, since it may be let go
    after the arm came to rest."""
    return system.body is None


@dataclass(frozen=True)
class ClosedLoopResult:
    """Time series at every control update ``k`` (K samples): ``t`` (K,), node positions ``x``
    (K, N+1, 2), node angles ``theta`` (K, N+1), sensed ``rho``, ``alpha`` (K, N+1), applied
    ``couple`` (K, N), ``penetration`` (K,) max surface penetration (m) and
    ``penetration_ratio`` (K,) max penetration / local radius, ``max_speed`` (K,) (m/s);
    ``max_penetration`` (m) and ``max_penetration_ratio``: their largest values over *every*
    control step, recorded or not (what the ROS simulator's ``LoopSession.max_penetration``
    reports, on the nodes and element centres);
    ``settled`` (quiet, and the run stayed valid: ``health``), ``settle_time`` (s or None),
    ``wall_time`` (s), ``newton_iterations``,
    the ``final_state`` and the run's ``model``, ``gains`` and ``config``; ``steps`` the control
    periods advanced and ``integrator_steps`` the accepted implicit steps (substeps included);
    the ``law`` that ran (:data:`~contgrasp_core.control.hold_law.LAWS`); a movable object's
    displacement ``object_q`` (K, 3: dx, dy m, dpsi rad) from its start pose, about its start
    ``object_centroid`` (both None while the object is fixed); ``health`` the run's validity and
    muscle effort (:class:`~contgrasp_core.rod.validity.RunHealth`)."""

    t: np.ndarray
    x: np.ndarray
    theta: np.ndarray
    rho: np.ndarray
    alpha: np.ndarray
    couple: np.ndarray
    penetration: np.ndarray
    penetration_ratio: np.ndarray
    max_speed: np.ndarray
    settled: bool
    settle_time: float | None
    wall_time: float
    newton_iterations: int
    final_state: RodState
    model: RodModel
    gains: FeedbackGains
    config: ClosedLoopConfig = field(repr=False)
    steps: int = 0
    integrator_steps: int = 0
    max_penetration: float = 0.0
    max_penetration_ratio: float = 0.0
    health: RunHealth | None = None
    law: str = "paper"
    object_q: np.ndarray | None = None
    object_centroid: tuple[float, float] | None = None

    def object_at(self, k: int, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 2) of the object at its start pose, moved to where it is at record ``k``
        (unchanged while it is fixed)."""
        if self.object_q is None or self.object_centroid is None:
            return np.asarray(points)
        return to_world(points, self.object_q[k], np.asarray(self.object_centroid))


def _speeds(system: RodSystem, st: RodState) -> float:
    """The largest node speed, and a movable object's largest speed within the arm's reach (m/s)."""
    model = system.model
    _, b = chain.frames(st.theta)
    v = np.cumsum(model.h * b * st.omega[:, None], axis=0)
    speed = float(np.hypot(v[:, 0], v[:, 1]).max())
    if system.body is not None and st.body is not None:
        speed = max(speed, system.body.max_speed(st.body, chain.nodes(model, st.theta)))
    return speed


def run_closed_loop(system: RodSystem, gains: FeedbackGains, config: ClosedLoopConfig = ClosedLoopConfig(),
                    state: RodState | None = None, law: Law | None = None) -> ClosedLoopResult:
    """Run the feedback loop (eq. (19) on the rod of eq. (17)) from ``state``
    (default: straight at rest) until ``config.duration``, or until settled when the object is
    fixed (:func:`stops_at_settle`). With a ``law``
    (:mod:`contgrasp_core.control.hold_law`) its command is asked once per period (``gains``
    then only names the run's paper gains in the result)."""
    if system.obstacle is None:
        raise InvalidParameterError("the closed loop needs an obstacle to sense (RodSystem.obstacle is None)")
    return _run(system, system.obstacle, gains, config, state, law)


def _run(system: RodSystem, obstacle: Obstacle, gains: FeedbackGains, config: ClosedLoopConfig,
         state: RodState | None, law: Law | None) -> ClosedLoopResult:
    from contgrasp_core.control.hold_law import ShapeHold
    from contgrasp_core.rod.integrator import RodLoads, StepFailedError

    m = system.model
    ei = m.joint_ei
    st = system.straight_state() if state is None else state
    period = config.period
    n_ctrl = int(np.ceil(config.duration / period - 1e-9))
    dt = period / config.substeps
    rec_every = 1 if config.record_period is None else max(1, int(round(config.record_period / period)))
    continuous = config.control_period is None
    r_nodes = m.radius(m.s_nodes)
    s_points = np.concatenate((m.s_nodes, m.s_centres))
    health = RunHealth(m)
    rec: dict[str, list] = {k: [] for k in ("t", "x", "theta", "rho", "alpha", "couple", "pen", "ratio", "speed", "q")}
    iters = 0
    steps = substeps = 0
    limit = config.max_iterations_per_period
    dt_next = dt
    settle = SettleDetector(config.settle_speed, config.settle_hold, config.min_time)
    stop_at_settle = stops_at_settle(system)
    max_pen = max_ratio = 0.0
    wall0 = time.perf_counter()
    for k in range(n_ctrl + 1):
        if system.body is not None:  # a movable object: sensed where it is at the start of the period
            obstacle = system.obstacle_at(st)
        shape = chain.arm_shape(m, st.theta)
        sn = sense(shape, obstacle, r_nodes)
        command = gains if law is None else law.command(sn.rho, sn.alpha, shape.theta, m.joint_curvature(st.theta),
                                                        period)
        if isinstance(command, ShapeHold):
            u = command.couple + command.couple_and_jacobian(st.theta, jacobian=False)[0]
        else:
            u = feedback_couple(sn.rho[:-1], sn.alpha[:-1], ei, command.mu1, command.mu2,
                                length_unit=command.length_unit)
        u = saturate(m, u)
        speed = _speeds(system, st)
        done = settle.update(st.t, speed, law is None or law.holding) and stop_at_settle
        pen_c = m.r_centres - obstacle.project(chain.centres(m, st.theta)).signed_distance
        pen = max(float(sn.delta.max()), float(pen_c.max()), 0.0)
        ratios = np.concatenate((sn.delta / r_nodes, pen_c / m.r_centres))
        ratio = max(float(ratios.max()), 0.0)
        health.observe(st.t, st.theta, ratios, s_points)
        max_pen, max_ratio = max(max_pen, pen), max(max_ratio, ratio)
        if k % rec_every == 0 or done or k == n_ctrl:
            for key, val in (("t", st.t), ("x", shape.r), ("theta", shape.theta),
                             ("rho", sn.rho), ("alpha", sn.alpha), ("couple", u), ("pen", pen), ("ratio", ratio),
                             ("speed", speed), ("q", None if st.body is None else st.body.q)):
                rec[key].append(val)
        if done or k == n_ctrl:
            break
        health.applied(st.t, u)
        if isinstance(command, ShapeHold):
            loads = RodLoads(couple=command.couple, feedback=command)
        else:
            loads = RodLoads(feedback=StateFeedback(m, obstacle, command)) if continuous else RodLoads(couple=u)
        st, info = system.advance(st, period, loads, dt_try=dt_next)
        dt_next = min(info["dt_next"], dt)
        iters += info["iterations"]
        steps += 1
        substeps += info["substeps"]
        if limit is not None and steps >= 100 and iters > limit * steps:
            raise StepFailedError(f"the rod engine took {iters} Newton iterations in {substeps} steps for {steps} control "
                                  f"periods by t = {st.t:.3g} s, more than {limit:g} per period: its steps fail and shrink "
                                  "(the arm touching itself, say)")
    wall = time.perf_counter() - wall0
    arr = {k: np.asarray(v) for k, v in rec.items()}
    return ClosedLoopResult(
        t=arr["t"], x=arr["x"], theta=arr["theta"], rho=arr["rho"], alpha=arr["alpha"], couple=arr["couple"],
        penetration=arr["pen"], penetration_ratio=arr["ratio"], max_speed=arr["speed"], settled=settle.settled and health.valid,
        settle_time=settle.settle_time if health.valid else None, wall_time=wall, newton_iterations=iters,
        final_state=st, model=m, gains=gains, config=config, steps=steps, integrator_steps=substeps,
        max_penetration=max_pen, max_penetration_ratio=max_ratio, health=health, **object_motion(system, rec["q"], law))


def object_motion(system: RodSystem, q: list[np.ndarray | None], law: Law | None) -> dict[str, Any]:
    """The :class:`ClosedLoopResult` fields of the ``law`` that ran (None: the paper's) and a
    movable object's recorded displacements ``q`` (each None while the object is fixed)."""
    body = system.body
    return {"law": "paper" if law is None else law.name, "object_q": None if body is None else np.array(q, dtype=float),
            "object_centroid": None if body is None else body.centroid}


def static_solution(res: ClosedLoopResult, obstacle_radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The theoretical static closed loop (eq. (8) with eq. (20)) from the
    rod's base state at the end of the run ``res``, for a circular object: (s, rho, alpha) on the
    rod nodes (Fig. 4's dashed curves)."""
    m, g = res.model, res.gains
    s = m.s_nodes
    mu2 = np.asarray(g.mu2, dtype=float)
    mu2_fn = (lambda si: np.interp(si, m.joint_s, mu2)) if mu2.ndim else float(mu2)
    sol = closed_loop_kinematics(float(res.rho[-1][0]), float(res.alpha[-1][0]), s, g.mu1, mu2_fn,
                                 1.0 / obstacle_radius, length_unit=g.length_unit)
    return s, sol.rho, sol.alpha
