"""The closed loop as explicit steps, shared by the core runner and the ROS nodes.

One control cycle k (paper Sec. V-B): :meth:`LoopSession.observe` (rod state k at the nodes: what
the simulator publishes), :func:`contgrasp_core.contact.sense` (eqs. (4), (5), Definition 1: what
the sensor does), :func:`contgrasp_core.control.feedback_at_joints` (eq. (19) and its first-order
expansion: what the controller does), :meth:`LoopSession.advance` (the couple held to first order
for one control period: what the simulator does). :meth:`LoopSession.check_divergence` tells a
broken run from a violent one. The ROS nodes call exactly these functions on exactly these
arrays, so a lock-step ROS run reproduces the core-only run bit for bit; :func:`run_sampled` is
that run, :func:`record_sampled` the same run recorded (``contgrasp simulate --hold first-order``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.arm import ArmShape
from contgrasp_core.contact import ContactState, sense
from contgrasp_core.control.hold_law import Law, ShapeHold
from contgrasp_core.control.rod_feedback import FeedbackExpansion, HeldExpansion
from contgrasp_core.errors import InvalidParameterError, RunFailure
from contgrasp_core.scenario import Scenario
from contgrasp_core.rod import chain
from contgrasp_core.rod.body import BodyState, shape_in_object_frame
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, ClosedLoopResult, SettleDetector, object_motion, stops_at_settle
from contgrasp_core.rod.integrator import RodLoads, RodState, RodSystem
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.muscle import saturate
from contgrasp_core.rod.obstacle import Obstacle
from contgrasp_core.rod.validity import RunHealth

__all__ = [
    "Observation",
    "LoopSession",
    "DivergenceLimits",
    "SimulationDivergedError",
    "run_sampled",
    "record_sampled",
    "drive",
    "sensed_shape",
    "preload",
]

Array = NDArray[np.float64]

Answer = FeedbackExpansion | ShapeHold
"""What the law answers a state with, held for one control period (:meth:`LoopSession.advance`)."""


@dataclass(frozen=True)
class Observation:
    """Rod state k at the N+1 nodes (SI): arclength ``s``, positions ``x`` (N+1, 2), tangent
    angles ``theta``, curvature ``kappa`` (joints; 0 at the free tip), radius, velocities ``v``
    (N+1, 2); kinetic energy, the largest surface penetration and node speed (the object's
    points included when it moves); ``body`` the movable object's state (None: fixed); the
    largest penetration over the local radius at the nodes and element centres (what the run's
    validity reads, :class:`~contgrasp_core.rod.validity.RunHealth`)."""

    k: int
    t: float
    s: Array
    x: Array
    theta: Array
    kappa: Array
    radius: Array
    v: Array
    kinetic_energy: float
    penetration: float
    max_speed: float
    body: BodyState | None = None
    penetration_ratio: float = 0.0

    @property
    def shape(self) -> ArmShape:
        """The centreline at the nodes, what :func:`contgrasp_core.contact.sense` senses."""
        return ArmShape(s=self.s, r=self.x, theta=self.theta)


class SimulationDivergedError(RunFailure):
    """The simulated state is no longer trustworthy (NaN/Inf, deep penetration, energy blow-up)."""


@dataclass(frozen=True)
class DivergenceLimits:
    """When a run counts as broken: the rod surface deeper inside the object than
    ``max_penetration`` (m) or a kinetic energy above ``max_kinetic_energy`` (J); NaN/Inf always.

    For scale, the paper scenario (docs/ros.md) peaks at 0.30 mm penetration (the 1 mm tip's
    impact at t ~ 0.16 s; 24 um once grasping) and 4.5e-4 J kinetic energy.
    """

    max_penetration: float
    max_kinetic_energy: float

    def __post_init__(self) -> None:
        if not (self.max_penetration > 0 and self.max_kinetic_energy > 0):
            raise InvalidParameterError("divergence limits must be > 0")


class LoopSession:
    """Steps a :class:`RodSystem` in control periods and decides when the run is over.

    The run finishes after ``duration``, or once the rod is quiet (every node slower than
    ``settle_speed`` for ``settle_hold`` seconds, not before ``min_time``) when the object is
    fixed (:func:`~contgrasp_core.rod.closed_loop.stops_at_settle`: a movable object is watched
    for the whole duration); both are judged on the observed state, before the couple for it is
    applied. It is settled when quiet at its last state (:class:`SettleDetector`) and still
    within the model's validity (``health``, :class:`~contgrasp_core.rod.validity.RunHealth`).
    """

    def __init__(self, system: RodSystem, config: ClosedLoopConfig, state: RodState | None = None) -> None:
        if system.obstacle is None:
            raise InvalidParameterError("the closed loop needs an obstacle (RodSystem.obstacle is None)")
        if config.control_period is None:
            raise InvalidParameterError("a sampled control loop needs config.control_period (the couple is held over it)")
        self.system = system
        self.obstacle: Obstacle = system.obstacle
        self.config = config
        self.state = system.straight_state() if state is None else state
        self.k = 0
        self.n_control = int(np.ceil(config.duration / config.control_period - 1e-9))
        self.dt = config.control_period / config.substeps
        self.settle = SettleDetector(config.settle_speed, config.settle_hold, config.min_time)
        self._stop_at_settle = stops_at_settle(system)
        self.finished = False
        self.iterations = 0
        self.max_penetration = 0.0
        self._observed: Observation | None = None
        self._radius = system.model.radius(system.model.s_nodes)  # (the same every step: shared, read-only)
        self._radius.flags.writeable = False
        self._surface_radius = np.concatenate((self._radius, system.model.r_centres))  # at the nodes and centres
        self._surface_s = np.concatenate((system.model.s_nodes, system.model.s_centres))
        self.health = RunHealth(system.model)

    @property
    def settled(self) -> bool:
        return self.settle.settled and self.health.valid

    @property
    def settle_time(self) -> float | None:
        return self.settle.settle_time if self.health.valid else None

    def observe(self, ready: bool = True) -> Observation:
        """Arrays of the current state; updates the settle/finish status (idempotent per step: the
        first call of a step decides). ``ready`` False (the law still in transition, e.g. the
        holding law before its hold) keeps the state from counting as settled."""
        if self._observed is not None and self._observed.k == self.k:
            return self._observed
        m, st = self.system.model, self.state
        _, b, x = chain.frames_and_nodes(m, st.theta)
        v = np.zeros_like(x)
        np.cumsum(m.h * b * st.omega[:, None], axis=0, out=v[1:])
        speed = float(np.hypot(v[:, 0], v[:, 1]).max())
        body = self.system.body
        if body is not None and st.body is not None:
            speed = max(speed, body.max_speed(st.body, x))
        radius = self._radius
        obstacle = self.system.obstacle_at(st)
        points = np.concatenate((x, 0.5 * (x[:-1] + x[1:])))  # the nodes and the centres (chain.centres)
        depth = self._surface_radius - obstacle.project(points).signed_distance
        pen = max(float(depth.max()), 0.0)
        self.max_penetration = max(self.max_penetration, pen)
        ratios = depth / self._surface_radius
        self.health.observe(float(st.t), st.theta, ratios, self._surface_s)
        obs = Observation(
            k=self.k,
            t=float(st.t),
            s=m.s_nodes,
            x=x,
            theta=chain.node_angles(m, st.theta),
            kappa=np.append(m.joint_curvature(st.theta), 0.0),
            radius=radius,
            v=v,
            kinetic_energy=self.system.kinetic_energy(st),
            penetration=pen,
            max_speed=speed,
            body=st.body,
            penetration_ratio=max(float(ratios.max()), 0.0),
        )
        self.settle.update(float(st.t), speed, ready)
        self.finished = (self.settle.settled and self._stop_at_settle) or self.k >= self.n_control
        self._observed = obs
        return obs

    def check_divergence(self, limits: DivergenceLimits, ready: bool = True) -> Observation:
        """The current observation (:meth:`observe` with ``ready``), or
        :class:`SimulationDivergedError` naming the cause when the state has NaN/Inf, its
        penetration exceeds ``limits.max_penetration`` or its kinetic energy
        ``limits.max_kinetic_energy``."""
        st = self.state
        if not (np.all(np.isfinite(st.theta)) and np.all(np.isfinite(st.omega))):
            raise SimulationDivergedError("simulation diverged: NaN/Inf in the rod state")
        obs = self.observe(ready)
        if not np.isfinite(obs.kinetic_energy) or obs.kinetic_energy > limits.max_kinetic_energy:
            raise SimulationDivergedError(
                f"simulation diverged: kinetic energy {obs.kinetic_energy:.3g} J above the limit "
                f"{limits.max_kinetic_energy:.3g} J (max_kinetic_energy)")
        if not obs.penetration <= limits.max_penetration:
            raise SimulationDivergedError(
                f"simulation diverged: the rod surface is {obs.penetration:.3g} m inside the object, "
                f"beyond the limit {limits.max_penetration:.3g} m (max_penetration_limit)")
        return obs

    def advance(self, couple: Array | FeedbackExpansion | ShapeHold, wrench: Array | None = None) -> None:
        """Hold the couple at the joints for one control period (integrator substeps).

        A plain array (N,) is a zero-order hold; a :class:`FeedbackExpansion` is held to first
        order in the state (:class:`HeldExpansion`), sensed against the object where it is at
        the start of the period; a :class:`~contgrasp_core.control.hold_law.ShapeHold` (the holding
        law's hold, linear in the state) is applied exactly. ``wrench`` (3,) is held on a movable
        object.
        """
        t, theta = float(self.state.t), self.state.theta
        if isinstance(couple, ShapeHold):
            self.health.applied(t, _applied_couple(self.system.model, couple, theta))
            self._step(RodLoads(couple=couple.couple, feedback=couple, wrench=wrench))
            return
        expansion = couple if isinstance(couple, FeedbackExpansion) else None
        u = np.asarray(expansion.u if expansion is not None else couple, dtype=float)
        n = self.system.model.n_elements
        if u.shape != (n,) or not np.isfinite(u).all():
            raise InvalidParameterError(f"couple must be {n} finite values, got {u.shape}")
        if expansion is not None:
            parts = (expansion.rho_ref, expansion.alpha_ref, expansion.g_rho, expansion.g_alpha)
            if any(np.shape(p) != (n,) for p in parts) or not np.isfinite(parts).all():
                raise InvalidParameterError(f"the feedback expansion needs {n} finite values per field")
        self.health.applied(t, saturate(self.system.model, u))  # (a held expansion's couple at the state it expands about)
        obstacle = self.system.obstacle_at(self.state)
        held = None if expansion is None else HeldExpansion(self.system.model, obstacle, expansion)
        self._step(RodLoads(couple=u, feedback=held, wrench=wrench))

    def _step(self, loads: RodLoads) -> None:
        """One control period of integrator substeps under ``loads``."""
        if self.finished:
            raise InvalidParameterError("the run is finished; reset to start again")
        st = self.state
        for _ in range(self.config.substeps):
            st, info = self.system.step(st, self.dt, loads)
            self.iterations += info["iterations"]
        self.state = st
        self.k += 1


def preload(system: RodSystem, config: ClosedLoopConfig) -> None:
    """Load the compiled kernels of a closed-loop step now (numba's on-disk cache: ~0.2 s for an
    observation, ~20 ms more for the first steps) by observing and stepping throwaway sessions
    once with each kind of couple (a plain array and a :class:`FeedbackExpansion`, zero), so a
    run's first steps are not late - in real time, a late step leaves the next ones with stale
    couples. ``system`` is not changed (a step is a function of the state it is given)."""
    zeros = np.zeros(system.model.n_elements)
    wrench = None if system.body is None else np.zeros(3)
    for couple in (zeros, FeedbackExpansion(u=zeros, rho_ref=zeros, alpha_ref=zeros, g_rho=zeros, g_alpha=zeros)):
        session = LoopSession(system, config)
        session.observe()
        session.advance(couple, wrench)


def sensed_shape(system: RodSystem, obs: Observation) -> ArmShape:
    """The arm as the sensor sees it against the object's own boundary: the observed centreline,
    or, for a movable object, the centreline in the object's frame (:func:`.body.shape_in_object_frame`)."""
    if system.body is None or obs.body is None:
        return obs.shape
    return shape_in_object_frame(obs.shape, obs.body.q, np.asarray(system.body.centroid))


def run_sampled(scenario: Scenario, system: RodSystem | None = None,
                until: Callable[[Observation, ContactState], bool] | None = None,
                law: Law | None = None,
                record: Callable[[LoopSession, Observation, ContactState, Answer], None] | None = None) -> LoopSession:
    """The scenario's sampled loop with the core functions only, stepped exactly as the ROS nodes
    step it (:func:`drive`, with the scenario's disturbance): a lock-step ROS run of the same
    scenario ends in the same state bit for bit. Returns the session, finished or stopped early
    by ``until(observation, contact)``; ``law`` and ``record`` as :func:`drive`'s."""
    system = scenario.system() if system is None else system
    session = LoopSession(system, scenario.loop)
    drive(session, scenario, None if scenario.disturbance is None else scenario.disturbance.wrench_at, until, law, record)
    return session


def record_sampled(scenario: Scenario, record_period: float | None = None, law: Law | None = None,
                   system: RodSystem | None = None) -> ClosedLoopResult:
    """:func:`run_sampled` recorded as a :class:`~contgrasp_core.rod.closed_loop.ClosedLoopResult`
    every ``record_period`` (s; None: every control period) and at the final state, which the law
    answers too: what ``contgrasp simulate --hold first-order`` reports and draws. The same steps,
    so it ends where :func:`run_sampled` of the scenario ends, bit for bit. ``max_penetration``
    and ``max_penetration_ratio`` are over every state, recorded or not."""
    wall0 = time.perf_counter()
    law = scenario.controller() if law is None else law
    config = replace(scenario.loop, record_period=record_period)
    period = scenario.loop.control_period
    every = 1 if record_period is None or period is None else max(1, int(round(record_period / period)))
    rows: dict[str, list[Any]] = {k: [] for k in ("t", "x", "theta", "rho", "alpha", "couple", "pen", "ratio", "speed", "q")}
    worst = 0.0

    def record(session: LoopSession, obs: Observation, contact: ContactState, answer: Answer) -> None:
        nonlocal worst
        worst = max(worst, obs.penetration_ratio)
        if obs.k % every == 0 or session.finished:
            for key, val in (("t", obs.t), ("x", obs.x), ("theta", obs.theta), ("rho", contact.rho),
                             ("alpha", contact.alpha), ("couple", _applied_couple(session.system.model, answer, session.state.theta)),
                             ("pen", obs.penetration), ("ratio", obs.penetration_ratio), ("speed", obs.max_speed),
                             ("q", None if obs.body is None else obs.body.q)):
                rows[key].append(val)

    session = run_sampled(scenario, system, law=law, record=record)
    arr = {k: np.asarray(v) for k, v in rows.items()}
    return ClosedLoopResult(
        t=arr["t"], x=arr["x"], theta=arr["theta"], rho=arr["rho"], alpha=arr["alpha"], couple=arr["couple"],
        penetration=arr["pen"], penetration_ratio=arr["ratio"], max_speed=arr["speed"], settled=session.settled,
        settle_time=session.settle_time, wall_time=time.perf_counter() - wall0, newton_iterations=session.iterations,
        final_state=session.state, model=session.system.model, gains=scenario.feedback_gains, config=config,
        steps=session.k, integrator_steps=session.k * config.substeps, max_penetration=session.max_penetration,
        max_penetration_ratio=worst, health=session.health, **object_motion(session.system, rows["q"], law))


def _applied_couple(model: RodModel, answer: Answer, theta: Array) -> Array:
    """The couple at the joints (N,) that ``answer`` applies at the element angles ``theta``
    (N,), bounded by the muscles (:func:`~contgrasp_core.rod.muscle.saturate`)."""
    if isinstance(answer, ShapeHold):
        return saturate(model, answer.couple + answer.couple_and_jacobian(theta, jacobian=False)[0])
    return saturate(model, np.asarray(answer.u, dtype=float))


def drive(session: LoopSession, scenario: Scenario, wrench: Callable[[float], Array] | None = None,
          until: Callable[[Observation, ContactState], bool] | None = None,
          law: Law | None = None,
          record: Callable[[LoopSession, Observation, ContactState, Answer], None] | None = None) -> Observation:
    """Step ``session`` as the ROS nodes do until it finishes or ``until(observation, contact)``
    holds: observe, :func:`~contgrasp_core.contact.sense` of the observation with the object's
    :class:`~contgrasp_core.boundary.Boundary` and the sensor's tolerance (``contact``, which
    ``until`` gets too), the law's command for the period (``law``, default a fresh
    :meth:`Scenario.controller`; the paper's gains go through
    :func:`~contgrasp_core.control.feedback_at_joints`), advance with ``wrench(t)`` on the object
    (t the period's start). With ``record``, ``record(session, observation, contact, answer)`` is
    told every state and the law's answer to it before it is held, the final state included
    (sensed and answered then too, as the graph's controller answers the last state; ``until``
    is not asked there). Returns the last observation."""
    from contgrasp_core.control import feedback_at_joints

    boundary = scenario.object.boundary()
    law = scenario.controller() if law is None else law
    period = session.config.control_period
    assert period is not None  # (LoopSession refuses a loop without one)
    system = session.system
    while True:
        obs = session.observe(law.holding)
        if session.finished and record is None:
            return obs
        c = sense(sensed_shape(system, obs), boundary, obs.radius, tol=scenario.sensing.contact_tolerance)
        if until is not None and not session.finished and until(obs, c):
            return obs
        command = law.command(c.rho, c.alpha, obs.theta, obs.kappa[:-1], period)
        answer = command if isinstance(command, ShapeHold) else feedback_at_joints(scenario.rod, command, c.rho, c.alpha)
        if record is not None:
            record(session, obs, c, answer)
        if session.finished:
            return obs
        session.advance(answer, None if wrench is None else wrench(obs.t))
