"""Implicit time integration of the reduced-coordinate rod (paper eqs. (17), (18)).

``M(theta) theta'' = Q(theta, theta')`` in the element angles (Lagrange; total joint couple
``EI kappa + u``, free tip), stepped by backward Euler (``"euler"``, the default) or the implicit
midpoint rule (``"midpoint"``) with Newton on the exact Newton matrix, assembled in O(N^2)
(:func:`.chain.gram_form`); with bounded muscles each Newton step backtracks on the residual's
norm (the saturation's kink). :meth:`RodSystem.advance` controls the step (halving, an accuracy
guard on the rotation per step, a linearly implicit fallback). By default the residual, matrix
and solve run in the compiled kernels (:mod:`contgrasp_core.rod._kernels`, the structured solve of
:mod:`.newton_matrix`); ``CONTGRASP_KERNELS=0`` selects the numpy path
(:meth:`RodSystem._evaluate`, the readable reference). docs/rod.md, "Integrator".
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from contgrasp_core.blas import single_thread_blas
from contgrasp_core.errors import InvalidParameterError, RunFailure
from contgrasp_core.rod import _kernels, chain
from contgrasp_core.rod.body import BodyState, RigidBody, to_object_frame
from contgrasp_core.rod.coupling import body_coupling
from contgrasp_core.rod.disturbance import wrench_array
from contgrasp_core.rod.loads import ContactFrame, contact_forces, contact_frame, contact_tensors, drag_forces
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.muscle import saturate, saturate_jacobian
from contgrasp_core.rod.newton_matrix import ChainMatrix, dense, solve
from contgrasp_core.rod.obstacle import Obstacle
from contgrasp_core.rod.self_contact import SelfContactFrame, missed_pairs, self_contact_frame, self_contact_load

__all__ = ["RodState", "RodLoads", "StepOptions", "RodSystem", "StepFailedError"]

_EMPTY = np.zeros(0)
_EMPTY2 = np.zeros((0, 2))
_EMPTY22 = np.zeros((0, 0))
_EMPTY_ROWS = np.zeros(0, dtype=np.int64)


class StepFailedError(RunFailure):
    """Newton did not converge even after the allowed step halvings (dt too large): a run
    failure (exit code 1), not bad input - the same parameters may succeed from another state."""


@dataclass(frozen=True)
class RodState:
    """Time ``t`` (s), element angles ``theta`` (N,) (rad) and rates ``omega`` (N,) (rad/s); the
    movable object's state ``body`` (None while the object is fixed); the stick-slip friction's
    ``anchors`` (N, 2), the object points (start-pose frame) where contacts stuck (NaN: none)."""

    t: float
    theta: np.ndarray
    omega: np.ndarray
    body: BodyState | None = None
    anchors: np.ndarray | None = None


class CoupleFeedback(Protocol):
    """A joint couple that depends on the rod state, applied implicitly inside Newton: its value
    (N,) at element angles ``theta`` and, with ``jacobian``, its derivative ``du/dtheta`` (N, N).
    ``nodes`` (N+1, 2) and element ``normals`` (N, 2) are passed when already computed."""

    def couple_and_jacobian(self, theta: np.ndarray, *, jacobian: bool = True, nodes: np.ndarray | None = None,
                            normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]: ...


@dataclass(frozen=True)
class RodLoads:
    """Applied loads: internal couple control ``couple`` at the joints ``s_k = k h`` (N,) in N m
    (eq. (17) ``u``, held over the step), point forces on the nodes (N+1, 2) in N, and an
    optional state feedback (a :class:`CoupleFeedback`, e.g.
    :class:`~contgrasp_core.control.StateFeedback`) whose couple is evaluated implicitly at the new
    state and added to ``couple``; ``wrench`` (3,) applied to a movable object (force x, y in N
    at its centroid, torque in N m)."""

    couple: np.ndarray | None = None
    node_forces: np.ndarray | None = None
    feedback: CoupleFeedback | None = None
    wrench: np.ndarray | None = None


@dataclass(frozen=True)
class StepOptions:
    """Integrator settings: ``method`` ("euler" | "midpoint"), Newton tolerance ``tol`` on the
    angle increment (rad), ``max_iter``, ``max_halvings``, contact search ``contact_margin`` (m),
    ``max_angle_step`` (rad) the largest element rotation accepted in one step; ``self_contact``
    the arm's contact with itself (:mod:`.self_contact`; off only to measure what it costs)."""

    method: str = "euler"
    tol: float = 1e-8
    max_iter: int = 12
    max_halvings: int = 10
    contact_margin: float = 2e-3
    max_angle_step: float = 0.5
    self_contact: bool = True

    def __post_init__(self) -> None:
        if self.method not in ("euler", "midpoint"):
            raise InvalidParameterError(f"method must be 'euler' or 'midpoint', got {self.method!r}")
        if not (self.tol > 0 and self.max_iter >= 1 and self.max_halvings >= 0 and self.contact_margin >= 0
                and self.max_angle_step > 0):
            raise InvalidParameterError(
                "need tol > 0, max_iter >= 1, max_halvings >= 0, contact_margin >= 0, max_angle_step > 0")


LAM_MIN = 2.0**-10
"""The shortest fraction of a Newton step the backtracking with bounded muscles takes
(:meth:`RodSystem._damped`): ten halvings (with four, 2.5 s of the reactive grasp at 50 kPa took
12 CPU-s against 1)."""


@dataclass(frozen=True, kw_only=True)
class _StepEval:
    """What a Newton iteration reports besides the residual and matrix: the deepest penetration
    of the object, the deepest overlap of the arm with itself and the stick-slip anchors after a
    step ending at this iterate."""

    penetration: float
    anchors: np.ndarray | None = None
    self_overlap: float = 0.0


@dataclass(frozen=True, kw_only=True)
class _Eval(_StepEval):
    q: np.ndarray
    mass: np.ndarray
    jac_w: np.ndarray
    jac_q: np.ndarray
    jac_m: np.ndarray


def _muscles(model: RodModel, loads: RodLoads, theta: np.ndarray, x: np.ndarray,
             b: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """The loads' active couple at ``theta`` as (held couple, feedback couple, its ``du/dtheta``),
    each None when absent; with bounded muscles (:mod:`.muscle`) their saturated sum is returned as
    the feedback couple, with the saturation's Jacobian."""
    u = du = None
    if loads.feedback is not None:
        u, du = loads.feedback.couple_and_jacobian(theta, jacobian=True, nodes=x, normals=b)
        assert du is not None  # asked for with jacobian=True
    if model.muscle_bound is None:
        return loads.couple, u, du
    n = model.n_elements
    total = (np.zeros(n) if loads.couple is None else np.asarray(loads.couple, dtype=float)) + (0.0 if u is None else u)
    return None, saturate(model, total), saturate_jacobian(model, total, np.zeros((n, n)) if du is None else du)


@dataclass(frozen=True)
class RodSystem:
    """A rod (:class:`RodModel`) and an optional obstacle, fixed or (with ``body``) a rigid body
    that the contact moves (:mod:`contgrasp_core.rod.body`); the integrator's entry point.

    With a body the step's unknowns are the rod's rates and the object's velocity ``(vx, vy,
    omega)``, solved together by Newton with the exact matrix (:mod:`contgrasp_core.rod.coupling`);
    without one (a fixed object) the step is exactly what it was before bodies existed."""

    model: RodModel
    obstacle: Obstacle | None = None
    options: StepOptions = field(default_factory=StepOptions)
    body: RigidBody | None = None

    def __post_init__(self) -> None:
        if self.body is not None and self.obstacle is None:
            raise InvalidParameterError("a movable object (body) needs its obstacle (the object's boundary)")
        _kernels.load()  # numba and the compiled kernels, at set-up rather than in the first step

    @property
    def _coupled_contact(self) -> bool:
        """Contact by :mod:`.coupling` (a movable object or stick-slip friction), else the kernels' own."""
        return self.body is not None or (self.model.friction > 0 and self.model.friction_model == "stick")

    # ---------------------------------------------------------------- states and energies
    def straight_state(self, t: float = 0.0) -> RodState:
        """The straight rod at rest along the base angle."""
        n = self.model.n_elements
        return RodState(t=t, theta=np.full(n, float(self.model.base_angle)), omega=np.zeros(n),
                        body=None if self.body is None else BodyState.rest())

    def kinetic_energy(self, state: RodState) -> float:
        """``1/2 omega^T M omega`` of the rod, plus the object's ``1/2 v^T M_o v`` (J)."""
        extra = 0.0
        if self.body is not None and state.body is not None:
            extra = 0.5 * float(np.sum(self.body.mass_matrix * state.body.v**2))
        if _kernels.ENABLED:
            m = self.model
            return float(_kernels.kinetic_energy(_kernels.f64(state.theta), _kernels.f64(state.omega), m.h, m.mass,
                                                 m.rot_inertia)) + extra
        return float(0.5 * state.omega @ chain.mass_matrix(self.model, state.theta) @ state.omega) + extra

    def elastic_energy(self, state: RodState, loads: RodLoads | None = None) -> float:
        """Bending energy ``sum 1/2 EI kappa^2 D`` plus the potential ``sum u kappa D`` of a held
        couple and ``-f . x`` of held node forces (J)."""
        m = self.model
        kap = m.joint_curvature(state.theta)
        e = 0.5 * np.sum(m.joint_ei * kap**2 * m.joint_len)
        if loads is not None and loads.couple is not None:
            e += np.sum(saturate(m, np.asarray(loads.couple, dtype=float)) * kap * m.joint_len)
        if loads is not None and loads.node_forces is not None:
            e -= np.sum(np.asarray(loads.node_forces) * chain.nodes(m, state.theta))
        if self.body is not None and state.body is not None:
            e += 0.5 * np.sum(np.asarray(self.body.stiffness) * state.body.q**2)
            if loads is not None and loads.wrench is not None:
                e -= np.sum(np.asarray(loads.wrench) * state.body.q)
        return float(e)

    def energy(self, state: RodState, loads: RodLoads | None = None) -> float:
        """Total mechanical energy (J)."""
        return self.kinetic_energy(state) + self.elastic_energy(state, loads)

    # ---------------------------------------------------------------- forces
    def _evaluate(self, theta: np.ndarray, omega: np.ndarray, loads: RodLoads, frame: ContactFrame | None,
                  delta: np.ndarray) -> _Eval:
        """Generalised force ``q`` at (``theta``, ``omega``) and the derivatives for the Newton
        matrix: ``jac_w = -dq/domega``, ``jac_q = -dq/dtheta`` and ``jac_m = d(M delta)/dtheta``
        (``delta`` the rate increment of the step). Exact for the model as stepped (the contact
        frame is frozen over the step by design)."""
        m = self.model
        n = m.n_elements
        h = m.h
        cs, sn = np.cos(theta), np.sin(theta)
        a = np.empty((n, 2))
        a[:, 0], a[:, 1] = cs, sn
        b = np.empty((n, 2))
        b[:, 0], b[:, 1] = -sn, cs
        cos_d = np.multiply.outer(cs, cs) + np.multiply.outer(sn, sn)  # cos(theta_j - theta_k) = b_j . b_k
        sin_d = np.multiply.outer(sn, cs) - np.multiply.outer(cs, sn)  # sin(theta_j - theta_k) = a_j . b_k
        hw = (h**2) * m.weight_matrix
        translational = hw * cos_d  # the mass matrix without the rotary inertia
        mass = translational.copy()
        diag = np.diag_indices(n)
        mass[diag] += m.rot_inertia
        ws = hw * sin_d
        x = np.empty((n + 1, 2))
        x[0] = m.base_position
        np.cumsum(h * a, axis=0, out=x[1:])
        x[1:] += x[0]
        c = 0.5 * (x[:-1] + x[1:])
        # centre velocities and centripetal accelerations (chain.centre_velocities / ...accelerations)
        bw = h * b * omega[:, None]
        aw = -h * a * (omega**2)[:, None]
        v = 0.5 * bw
        v[1:] += np.cumsum(bw[:-1], axis=0)
        acc = 0.5 * aw
        acc[1:] += np.cumsum(aw[:-1], axis=0)
        f = -m.mass[:, None] * acc
        # inertia: d(M delta)/dtheta, and the centripetal forces' derivatives (both O(N^2))
        jac_m = ws * delta
        jac_m[diag] -= ws @ delta
        jac_q = m.stiffness_matrix - translational * omega**2
        jac_w = 2.0 * ws * omega
        if m.damping > 0:
            jac_w += m.damping * mass
            jac_q += m.damping * (ws * omega)
            jac_q[diag] -= m.damping * (ws @ omega)
        pen = 0.0
        damp = np.zeros((4, n))  # per-centre -df/dv tensors (xx, xy, yx, yy) of drag and contact
        if m.drag_normal > 0 or m.drag_tangential > 0:
            fd, gn, gt = drag_forces(m, a, b, v)
            f += fd
            damp += chain.outer_entries(gn, b, b) + chain.outer_entries(gt, a, a)
            # rotation of element i's own frame at fixed velocity
            vn, vt = np.sum(v * b, axis=1), np.sum(v * a, axis=1)
            fn_, ft_ = np.sum(fd * b, axis=1), np.sum(fd * a, axis=1)
            e = (gn * vt + ft_)[:, None] * b - (gt * vn + fn_)[:, None] * a
            jac_q -= h * chain.lower_weights(n).T * (b @ e.T)
        if frame is not None:
            cl = contact_forces(m, frame, c, v)
            f += cl.forces
            if np.any(cl.stiffness > 0) or np.any(cl.friction_damping > 0):
                stiff, cdamp = contact_tensors(m, frame, cl)
                jac_q += chain.gram_form((h**2) * stiff, b, b)
                damp += cdamp
            pen = float(max(cl.penetration.max(), 0.0))
        if damp.any():  # G^T D G, and the same through the velocities' dependence on the angles
            damp *= h**2
            jac_w += chain.gram_form(damp, b, b)
            jac_q -= chain.gram_form(damp, b, a) * omega
        tail = np.zeros_like(f)
        np.cumsum(f[:0:-1], axis=0, out=tail[-2::-1])
        tail += 0.5 * f
        if loads.node_forces is not None:
            fn_ = np.asarray(loads.node_forces, dtype=float)
            tail += np.cumsum(fn_[:0:-1], axis=0)[::-1]
        q = h * np.sum(b * tail, axis=1)
        jac_q[np.diag_indices(n)] += h * np.sum(a * tail, axis=1)
        mom = m.joint_ei * m.joint_curvature(theta)
        couple, u, du = _muscles(m, loads, theta, x, b)
        if couple is not None:
            mom = mom + couple
        if u is not None and du is not None:
            mom = mom + u
            jac_q += du
            jac_q[:-1] -= du[1:]
        q -= mom
        q[:-1] += mom[1:]
        if m.damping > 0:
            q -= m.damping * (mass @ omega)
        return _Eval(q=q, mass=mass, jac_w=jac_w, jac_q=jac_q, jac_m=jac_m, penetration=pen)

    def _newton_system_compiled(self, theta: np.ndarray, omega: np.ndarray, delta: np.ndarray, dt: float,
                                cw: float, cq: float, loads: RodLoads,
                                frame: ContactFrame | None) -> tuple[np.ndarray, ChainMatrix, _StepEval]:
        """:meth:`newton_system` by :func:`._kernels.newton_system` (same terms as :meth:`_evaluate`)."""
        m = self.model
        f64 = _kernels.f64
        theta = f64(theta)
        base = m.base
        a, b, x = _kernels.frames_nodes(theta, m.h, base)
        held, u_, du_ = _muscles(m, loads, theta, x, b)
        u_fb, du = (_EMPTY, _EMPTY22) if u_ is None or du_ is None else (f64(u_), f64(du_))
        couple = _EMPTY if held is None else f64(held)
        nf = _EMPTY2 if loads.node_forces is None else f64(loads.node_forces)
        if frame is None:
            rows, foot, normal, tangent = _EMPTY_ROWS, _EMPTY2, _EMPTY2, _EMPTY2
        else:
            rows = np.require(frame.rows, dtype=np.int64, requirements=("C", "W"))
            foot, normal, tangent = f64(frame.foot), f64(frame.normal), f64(frame.tangent)
        res, lower, up, band, pen = _kernels.newton_system(
            theta, f64(omega), f64(delta), float(dt), float(cw), float(cq), m.h, base, m.rot_inertia, m.mass,
            float(m.damping), float(m.drag_normal), float(m.drag_tangential), m.r_centres, m.stiffness_matrix,
            m.joint_ei, m.joint_len, float(m.base_angle), couple, nf, rows, foot, normal, tangent,
            float(m.contact_stiffness), float(m.contact_damping), float(m.friction), float(m.friction_velocity),
            u_fb, du, a, b, x)
        return res, ChainMatrix(lower, a, up, band), _StepEval(penetration=float(pen))

    # ---------------------------------------------------------------- stepping
    def step(self, state: RodState, dt: float, loads: RodLoads = RodLoads()) -> tuple[RodState, dict]:
        """Advance by ``dt`` (s) with ``loads`` held constant: one implicit step, or adaptive
        sub-steps (see :meth:`advance`) if Newton fails or the accuracy guard trips.

        Returns the new state and ``info`` with ``iterations`` (Newton iterations, all attempts),
        ``substeps`` (accepted steps) and ``penetration`` (max surface penetration seen, m).
        """
        return self.advance(state, dt, loads, dt_try=dt)

    def advance(self, state: RodState, duration: float, loads: RodLoads = RodLoads(),
                dt_try: float | None = None) -> tuple[RodState, dict]:
        """Advance by ``duration`` (s) with adaptive steps (module docstring): start from ``dt_try``
        (default: the whole duration). ``info["dt_next"]`` is the step to try next time."""
        if not (np.isfinite(duration) and duration > 0):
            raise InvalidParameterError(f"dt/duration must be finite and > 0, got {duration!r}")
        if loads.wrench is not None:
            if self.body is None:
                raise InvalidParameterError("a wrench on the object needs a movable object (the object is fixed)")
            wrench_array("the object's wrench", loads.wrench)
        with single_thread_blas():  # (contgrasp_core.blas: small dense solves, one thread)
            return self._advance(state, duration, loads, dt_try)

    def _advance(self, state: RodState, duration: float, loads: RodLoads,
                 dt_try: float | None) -> tuple[RodState, dict]:
        info = {"iterations": 0, "substeps": 0, "penetration": 0.0, "self_overlap": 0.0}
        dt = duration if dt_try is None else min(float(dt_try), duration)
        dt_min = duration / 2.0**self.options.max_halvings
        dt_linear = duration / 2.0 ** min(4, self.options.max_halvings)  # see _linearly_implicit_step
        t_end = state.t + duration
        rate_change: np.ndarray | None = None  # d omega / dt of the last accepted step
        while t_end - state.t > 1e-12 * max(1.0, abs(t_end)):
            h = min(dt, t_end - state.t)
            new, factor = self._try_step(state, h, loads, info, rate_change)
            if new is None and h <= dt_linear * (1 + 1e-9):
                new = self._linearly_implicit_step(state, h, loads, info)
                factor = 0.5 if new is None else 1.0
            if new is None:
                if h <= dt_min * (1 + 1e-9):
                    raise StepFailedError(f"Newton failed to converge at t={state.t:.6g} s even with dt={h:.3g} s")
                dt = max(h * factor, dt_min)
                continue
            rate_change = (self.rates(new) - self.rates(state)) / h
            state = new
            if h >= dt * (1 - 1e-9) or factor < 1.0:  # (a shortened last step says nothing about growth)
                dt = min(h * factor, duration)
        info["dt_next"] = dt
        return state, info

    def newton_system(self, state: RodState, w1: np.ndarray, dt: float, loads: RodLoads = RodLoads(),
                      frame: ContactFrame | None = None,
                      self_frame: SelfContactFrame | None = None) -> tuple[np.ndarray, np.ndarray, _StepEval]:
        """:meth:`_newton_system` with the Newton matrix as an (N, N) array (the step itself solves
        the structured :class:`.newton_matrix.ChainMatrix` where it has one)."""
        res, jac, ev = self._newton_system(state, w1, dt, loads, frame, self_frame)
        return res, dense(jac), ev

    def _scheme(self, state: RodState, w1: np.ndarray, dt: float) -> tuple[float, float, np.ndarray, np.ndarray]:
        """The scheme's weights ``cw``, ``cq`` of the rate and angle derivatives and the angles and
        rates at which it evaluates forces (the step's end, or its midpoint)."""
        n = len(state.theta)
        midpoint = self.options.method == "midpoint"
        cw, cq = (0.5, 0.25 * dt) if midpoint else (1.0, dt)
        wr1 = w1[:n]
        w_ = 0.5 * (state.omega + wr1) if midpoint else wr1
        return cw, cq, state.theta + (0.5 if midpoint else 1.0) * dt * w_, w_

    def _newton_system(self, state: RodState, w1: np.ndarray, dt: float, loads: RodLoads,
                       frame: ContactFrame | None, self_frame: SelfContactFrame | None = None,
                       ) -> tuple[np.ndarray, np.ndarray | ChainMatrix, _StepEval]:
        """:meth:`_object_newton_system` and the arm's contact with itself (``self_frame``: the
        step's frozen pairs, :mod:`.self_contact`), whose terms join the rod's rows; a step where no
        pair presses is exactly the system without them."""
        res, jac, ev = self._object_newton_system(state, w1, dt, loads, frame)
        if self_frame is None:
            return res, jac, ev
        cw, cq, th_, w_ = self._scheme(state, w1, dt)
        load = self_contact_load(self.model, self_frame, th_, w_)
        if load is None:
            return res, jac, ev
        n = len(th_)
        full = dense(jac).copy()
        full[:n, :n] -= dt * (cw * load.q_omega + cq * load.q_theta)
        res = res.copy()
        res[:n] -= dt * load.q
        return res, full, replace(ev, self_overlap=load.overlap)

    def _object_newton_system(self, state: RodState, w1: np.ndarray, dt: float, loads: RodLoads,
                              frame: ContactFrame | None) -> tuple[np.ndarray, np.ndarray | ChainMatrix, _StepEval]:
        """Residual and Newton matrix of the implicit step from ``state`` over ``dt`` at the
        iterate ``w1`` (the new rates): backward Euler ``R = M(theta_1)(w1 - w0) - dt q(theta_1,
        w1)`` with ``theta_1 = theta_0 + dt w1``, or the implicit midpoint rule with both evaluated
        at the midpoint; ``frame`` is the step's frozen contact frame.

        With a movable object ``w1`` is (N+3,): the rod's rates, then the object's velocity, whose
        residual ``M_o (v1 - v0) - dt F`` (Newton-Euler, :mod:`.body`) joins the system with the
        coupling blocks of :func:`.coupling.body_coupling`."""
        w0 = state.omega
        n = len(w0)
        midpoint = self.options.method == "midpoint"
        cw, cq, th_, w_ = self._scheme(state, w1, dt)
        wr1 = w1[:n]
        if not self._coupled_contact:
            return self._rod_newton_system(th_, w_, wr1 - w0, dt, cw, cq, loads, frame)
        res, rod_jac, _ = self._rod_newton_system(th_, w_, wr1 - w0, dt, cw, cq, loads, None)
        anchors = None if frame is None else frame.anchors
        if self.body is None:  # a fixed object with stick-slip friction
            zero = np.zeros(3)
            cp = body_coupling(self.model, None, frame, th_, w_, zero, zero, anchors=anchors)
            ev = _StepEval(penetration=cp.penetration, anchors=cp.anchors)
            if frame is None:  # no centre near the object: the frictionless rod's system, solved as it is
                return res, rod_jac, ev
            return res - dt * cp.rod, dense(rod_jac) - dt * (cw * cp.rod_omega + cq * cp.rod_theta), ev
        jac = dense(rod_jac)
        body, bs = self.body, state.body
        assert bs is not None  # (a system with a body steps states with one)
        vb1 = w1[n:]
        vb_ = 0.5 * (bs.v + vb1) if midpoint else vb1
        q_ = bs.q + (0.5 if midpoint else 1.0) * dt * vb_
        cp = body_coupling(self.model, body, frame, th_, w_, q_, vb_, loads.wrench, anchors)
        full = np.empty((n + 3, n + 3))
        full[:n, :n] = jac - dt * (cw * cp.rod_omega + cq * cp.rod_theta)
        full[:n, n:] = -dt * (cw * cp.rod_v + cq * cp.rod_q)
        full[n:, :n] = -dt * (cw * cp.wrench_omega + cq * cp.wrench_theta)
        full[n:, n:] = np.diag(body.mass_matrix) - dt * (cw * cp.wrench_v + cq * cp.wrench_q)
        res = np.concatenate([res - dt * cp.rod, body.mass_matrix * (vb1 - bs.v) - dt * cp.wrench])
        return res, full, _StepEval(penetration=cp.penetration, anchors=cp.anchors)

    def _rod_newton_system(self, th_: np.ndarray, w_: np.ndarray, delta: np.ndarray, dt: float, cw: float,
                           cq: float, loads: RodLoads,
                           frame: ContactFrame | None) -> tuple[np.ndarray, np.ndarray | ChainMatrix, _StepEval]:
        """The rod's residual and Newton matrix, forces evaluated at (``th_``, ``w_``), with
        ``delta`` the rate increment of the step (compiled kernels or the numpy reference)."""
        if _kernels.ENABLED:
            return self._newton_system_compiled(th_, w_, delta, dt, cw, cq, loads, frame)
        ev = self._evaluate(th_, w_, loads, frame, delta)
        res = ev.mass @ delta - dt * ev.q
        return res, ev.mass + dt * cw * ev.jac_w + cq * (dt * ev.jac_q + ev.jac_m), ev

    def contact_frame(self, state: RodState, dt: float) -> ContactFrame | None:
        """The tangent-line contact model frozen over a step of ``dt`` from ``state`` (None
        without an obstacle or with no centre near it)."""
        if self.obstacle is None:
            return None
        m, th0, w0 = self.model, state.theta, state.omega
        x = chain.frames_and_nodes(m, th0 + 0.5 * dt * w0)[2]
        c0 = 0.5 * (x[:-1] + x[1:])  # (chain.centres)
        margin = self.options.contact_margin + 2.0 * dt * np.abs(w0).max() * m.length
        bs = state.body
        if self.body is None or bs is None:
            frame = contact_frame(m, self.obstacle, c0, margin)
        else:  # a movable object: the frame in the object's start-pose frame, at its mid-step pose
            margin += 2.0 * dt * self.body.max_speed(bs, c0)
            frame = contact_frame(m, self.obstacle, to_object_frame(c0, bs.q + 0.5 * dt * bs.v,
                                                                    np.asarray(self.body.centroid)), margin)
        if frame is None or not (m.friction > 0 and m.friction_model == "stick"):
            return frame
        # stick-slip: the anchors the step starts from; a new contact sticks where it is (its
        # centre at the start of the step, in the object's frame)
        start = chain.centres(m, th0)
        if self.body is not None and bs is not None:
            start = to_object_frame(start, bs.q, np.asarray(self.body.centroid))
        anchors = np.full((m.n_elements, 2), np.nan) if state.anchors is None else state.anchors.copy()
        new = frame.rows[np.isnan(anchors[frame.rows, 0])]
        anchors[new] = start[new]
        return replace(frame, anchors=anchors)

    def self_contact_frame(self, state: RodState, dt: float) -> SelfContactFrame | None:
        """The pairs of the arm near itself, frozen over a step of ``dt`` from ``state``
        (:mod:`.self_contact`; None when no two parts are within the contact margin)."""
        return self._self_contact_search(state, dt)[0]

    def _self_contact_search(self, state: RodState,
                             dt: float) -> tuple[SelfContactFrame | None, np.ndarray | None, float]:
        """:meth:`self_contact_frame`, the centres it searched (the step's predicted midpoint)
        and its margin (m); (None, None, 0) with self-contact off."""
        if not self.options.self_contact:
            return None, None, 0.0
        m, w0 = self.model, state.omega
        _, b, x = chain.frames_and_nodes(m, state.theta + 0.5 * dt * w0)
        speed = np.hypot(*np.cumsum(m.h * b * w0[:, None], axis=0).T).max()  # the fastest node (m/s)
        margin = self.options.contact_margin + 2.0 * dt * speed  # (two parts close at most twice as fast)
        c = 0.5 * (x[:-1] + x[1:])
        return self_contact_frame(m, c, margin), c, margin

    def obstacle_at(self, state: RodState) -> Obstacle:
        """The object where it is in ``state`` (the obstacle itself while it is fixed)."""
        if self.obstacle is None:
            raise InvalidParameterError("the system has no obstacle")
        if self.body is None or state.body is None:
            return self.obstacle
        return self.obstacle.moved(state.body.q, np.asarray(self.body.centroid))

    def rates(self, state: RodState) -> np.ndarray:
        """The step's unknowns at ``state``: the rod's rates, and the object's velocity when it moves."""
        if self.body is None:
            return state.omega
        assert state.body is not None  # (a system with a body steps states with one)
        return np.concatenate([state.omega, state.body.v])

    def _new_state(self, state: RodState, w1: np.ndarray, dt: float, anchors: np.ndarray | None = None) -> RodState:
        """The state after a step to the unknowns ``w1`` (:meth:`rates`) under the chosen scheme,
        with the stick-slip ``anchors`` the step ended with."""
        n = len(state.theta)
        if self.body is None:
            return RodState(t=state.t + dt, theta=self._new_angles(state, w1[:n], dt), omega=w1[:n], anchors=anchors)
        bs = state.body
        assert bs is not None  # (a system with a body steps states with one)
        vb1 = w1[n:]
        vb = 0.5 * (bs.v + vb1) if self.options.method == "midpoint" else vb1
        return RodState(t=state.t + dt, theta=self._new_angles(state, w1[:n], dt), omega=w1[:n],
                        body=BodyState(q=bs.q + dt * vb, v=vb1), anchors=anchors)

    def _new_angles(self, state: RodState, w1: np.ndarray, dt: float) -> np.ndarray:
        """The angles after a step to the rates ``w1`` under the chosen scheme."""
        w = 0.5 * (state.omega + w1) if self.options.method == "midpoint" else w1
        return state.theta + dt * w

    def _linearly_implicit_step(self, state: RodState, dt: float, loads: RodLoads, info: dict) -> RodState | None:
        """One Newton iteration from the old rates (linearly implicit Euler), for a step Newton
        cannot converge even after four halvings: the residual jumps there, e.g. when a joint's
        closest point on a non-convex object switches lobes and the feedback couple with it (the
        implicit equation may have no root, and halving on to tiny steps only chatters). Stable
        for the stiff linear part, first order like backward Euler; None if it would rotate an
        element by more than ``max_angle_step``. Counted in ``info["linearised_steps"]``."""
        frame, self_frame = self.contact_frame(state, dt), self.self_contact_frame(state, dt)
        z0 = self.rates(state)
        res, jac, ev = self._newton_system(state, z0, dt, loads, frame, self_frame)
        w1 = z0 + solve(jac, -res)
        new = self._new_state(state, w1, dt, ev.anchors)
        info["iterations"] += 1
        if not (np.all(np.isfinite(w1)) and np.abs(new.theta - state.theta).max() <= self.options.max_angle_step):
            return None
        info["linearised_steps"] = info.get("linearised_steps", 0) + 1
        info["substeps"] += 1
        _account(info, ev)
        return new

    def _try_step(self, state: RodState, dt: float, loads: RodLoads, info: dict,
                  rate_change: np.ndarray | None = None) -> tuple[RodState | None, float]:
        """One implicit step; returns the new state (None if rejected) and the factor for the next
        step (module docstring). ``rate_change`` extrapolates the first Newton iterate. A step
        that ends with parts of the arm overlapping that its self-contact frame did not foresee is
        solved again with them (:func:`.self_contact.missed_pairs`, at most twice)."""
        frame = self.contact_frame(state, dt)
        self_frame, searched, margin = self._self_contact_search(state, dt)
        w0 = self.rates(state)
        first = w0.copy() if rate_change is None else w0 + dt * rate_change
        for _ in range(3):
            w1, ev, it = self._newton(state, dt, loads, frame, self_frame, first)
            info["iterations"] += it
            if w1 is None or ev is None:
                return None, 0.5
            new = self._new_state(state, w1, dt, ev.anchors)
            missed = None if searched is None else self._missed(state, new, self_frame, searched, margin)
            if missed is None:
                break
            self_frame = missed
        assert ev is not None  # (a failed solve returned above)
        turn = np.abs(new.theta - state.theta).max() / self.options.max_angle_step
        if turn > 1.0:
            return None, 0.9 / turn  # accuracy guard: too large a rotation in one step
        info["substeps"] += 1
        _account(info, ev)
        grow = 2.0 if it <= self.options.max_iter // 2 else 1.0
        return new, min(grow, 0.9 / max(turn, 1e-12))

    def _newton(self, state: RodState, dt: float, loads: RodLoads, frame: ContactFrame | None,
                self_frame: SelfContactFrame | None,
                w1: np.ndarray) -> tuple[np.ndarray | None, _StepEval | None, int]:
        """Newton from the iterate ``w1``: the step's unknowns, the last evaluation and the
        iterations (None, None when it diverges or does not converge in ``max_iter``)."""
        opt, n = self.options, len(state.theta)
        prev = np.inf
        scale = 1.0 + np.abs(state.theta).max()
        damped = self.model.muscle_bound is not None
        res, jac, ev = self._newton_system(state, w1, dt, loads, frame, self_frame)
        for it in range(1, opt.max_iter + 1):
            dw = solve(jac, -res)
            if self.body is not None:  # the object's translation in rod lengths, beside the angles
                dw_scaled = dw.copy()
                dw_scaled[n:n + 2] /= self.model.length
                size = dt * np.abs(dw_scaled).max()
            else:
                size = dt * np.abs(dw).max()
            if not np.isfinite(size) or (it >= 3 and size > 2.0 * prev):  # diverging: give up early
                return None, None, it
            prev = size
            if size <= opt.tol * (scale + dt * np.abs(w1[:n] + dw[:n]).max()):
                return w1 + dw, ev, it
            if it == opt.max_iter:
                break
            if damped:  # (the saturation's kink: a full step may cross it and cycle)
                w1, (res, jac, ev) = self._damped(state, dt, loads, frame, self_frame, w1, dw, res)
            else:
                w1 = w1 + dw
                res, jac, ev = self._newton_system(state, w1, dt, loads, frame, self_frame)
        return None, None, opt.max_iter

    def _damped(self, state: RodState, dt: float, loads: RodLoads, frame: ContactFrame | None,
                self_frame: SelfContactFrame | None, w1: np.ndarray, dw: np.ndarray,
                res: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray | ChainMatrix, _StepEval]]:
        """The Newton step ``dw`` from ``w1`` shortened until the residual's norm decreases
        (Armijo backtracking, down to :data:`LAM_MIN`): with bounded muscles the residual is
        only piecewise smooth (:func:`.muscle.saturate`), and a full step across a joint's
        saturation kink can cycle between its two sides. The new iterate and its system."""
        f0 = float(np.linalg.norm(res))
        lam = 1.0
        while True:
            trial = w1 + lam * dw
            system = self._newton_system(state, trial, dt, loads, frame, self_frame)
            if lam <= LAM_MIN or float(np.linalg.norm(system[0])) <= (1.0 - 1e-4 * lam) * f0:
                return trial, system
            lam *= 0.5

    def _missed(self, state: RodState, new: RodState, self_frame: SelfContactFrame | None, searched: np.ndarray,
                margin: float) -> SelfContactFrame | None:
        """The step's self-contact frame with the pairs that overlap at its end unforeseen (None:
        none). No pair can have closed a gap wider than the search's ``margin`` if no centre moved
        half of it from where the search saw it (``searched``): then nothing is searched again."""
        m = self.model
        end = chain.centres(m, new.theta)
        if 2.0 * float(np.hypot(*(end - searched).T).max()) < margin:
            return None
        return missed_pairs(m, self_frame, chain.centres(m, state.theta), end)


def _account(info: dict, ev: _StepEval) -> None:
    """An accepted step's deepest penetration and self-overlap into the step's ``info``."""
    info["penetration"] = max(info["penetration"], ev.penetration)
    info["self_overlap"] = max(info["self_overlap"], ev.self_overlap)
