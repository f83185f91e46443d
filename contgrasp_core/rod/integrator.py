"""Implicit time integration of the reduced-coordinate rod (paper eq. dynamics, boundary_conditions).

Equations of motion (Lagrange, generalised coordinates ``theta``):

``M(theta) theta'' = Q(theta, theta')`` with
``Q = G^T (f_ext - m a_cent) - (m_k - m_{k+1}) - zeta M theta'`` where ``m_k = EI_k kappa_k + u_k``
is the total joint couple (``m_N = 0``: free tip), ``f_ext`` drag + contact (+ node loads),
``a_cent`` the centripetal accelerations and ``G`` the centre Jacobian (:mod:`.chain`).

Schemes (unknown ``omega_{n+1}``, solved by Newton with an approximate analytic Jacobian
``M + dt c_w (zeta M + D_drag + D_contact) + dt c_q (K + K_contact + K_geom)``; the residual is
exact, so the converged step is the exact implicit step):

* ``"euler"`` - backward Euler, first order, L-stable (default: robust with stiff contact);
* ``"midpoint"`` - implicit midpoint, second order, no numerical dissipation (energy error
  O(dt^2) and bounded for the undamped rod).

A step that does not converge in ``max_iter`` iterations is retried with half the step (at most
``max_halvings`` times below the requested step); so is a converged step that rotates any element
by more than ``max_angle_step`` (an accuracy guard for violent transients). :meth:`RodSystem.advance`
grows the step again after successes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import chain
from contgrasp_core.rod.control import StateFeedback
from contgrasp_core.rod.loads import contact_forces, contact_frame, contact_matrices, drag_forces
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.obstacle import Obstacle

__all__ = ["RodState", "RodLoads", "StepOptions", "RodSystem", "StepFailedError"]


class StepFailedError(InvalidParameterError):
    """Newton did not converge even after the allowed step halvings (dt too large)."""


@dataclass(frozen=True)
class RodState:
    """Time ``t`` (s), element angles ``theta`` (N,) (rad) and rates ``omega`` (N,) (rad/s)."""

    t: float
    theta: np.ndarray
    omega: np.ndarray


@dataclass(frozen=True)
class RodLoads:
    """Applied loads: internal couple control ``couple`` at the joints ``s_k = k h`` (N,) in N m
    (eq. dynamics ``u``, held over the step), point forces on the nodes (N+1, 2) in N, and an
    optional state feedback (:class:`~contgrasp_core.rod.control.StateFeedback`) whose couple is
    evaluated implicitly at the new state and added to ``couple``."""

    couple: np.ndarray | None = None
    node_forces: np.ndarray | None = None
    feedback: StateFeedback | None = None


@dataclass(frozen=True)
class StepOptions:
    """Integrator settings: ``method`` ("euler" | "midpoint"), Newton tolerance ``tol`` on the
    angle increment (rad), ``max_iter``, ``max_halvings``, contact search ``contact_margin`` (m),
    ``max_angle_step`` (rad) the largest element rotation accepted in one step."""

    method: str = "euler"
    tol: float = 1e-8
    max_iter: int = 12
    max_halvings: int = 10
    contact_margin: float = 2e-3
    max_angle_step: float = 0.5

    def __post_init__(self) -> None:
        if self.method not in ("euler", "midpoint"):
            raise InvalidParameterError(f"method must be 'euler' or 'midpoint', got {self.method!r}")
        if not (self.tol > 0 and self.max_iter >= 1 and self.max_halvings >= 0 and self.contact_margin >= 0
                and self.max_angle_step > 0):
            raise InvalidParameterError(
                "need tol > 0, max_iter >= 1, max_halvings >= 0, contact_margin >= 0, max_angle_step > 0")


@dataclass(frozen=True)
class _Eval:
    q: np.ndarray
    mass: np.ndarray
    jac_w: np.ndarray
    jac_q: np.ndarray
    penetration: float


@dataclass(frozen=True)
class RodSystem:
    """A rod (:class:`RodModel`) and an optional fixed obstacle; the integrator's entry point."""

    model: RodModel
    obstacle: Obstacle | None = None
    options: StepOptions = field(default_factory=StepOptions)

    # ---------------------------------------------------------------- states and energies
    def straight_state(self, t: float = 0.0) -> RodState:
        """The straight rod at rest along the base angle."""
        n = self.model.n_elements
        return RodState(t=t, theta=np.full(n, float(self.model.base_angle)), omega=np.zeros(n))

    def kinetic_energy(self, state: RodState) -> float:
        """``1/2 omega^T M omega`` (J)."""
        return float(0.5 * state.omega @ chain.mass_matrix(self.model, state.theta) @ state.omega)

    def elastic_energy(self, state: RodState, loads: RodLoads | None = None) -> float:
        """Bending energy ``sum 1/2 EI kappa^2 D`` plus the potential ``sum u kappa D`` of a held
        couple and ``-f . x`` of held node forces (J)."""
        m = self.model
        kap = m.joint_curvature(state.theta)
        e = 0.5 * np.sum(m.joint_ei * kap**2 * m.joint_len)
        if loads is not None and loads.couple is not None:
            e += np.sum(np.asarray(loads.couple) * kap * m.joint_len)
        if loads is not None and loads.node_forces is not None:
            e -= np.sum(np.asarray(loads.node_forces) * chain.nodes(m, state.theta))
        return float(e)

    def energy(self, state: RodState, loads: RodLoads | None = None) -> float:
        """Total mechanical energy (J)."""
        return self.kinetic_energy(state) + self.elastic_energy(state, loads)

    # ---------------------------------------------------------------- forces
    def _evaluate(self, theta: np.ndarray, omega: np.ndarray, loads: RodLoads, frame) -> _Eval:
        m = self.model
        n = m.n_elements
        cs, sn = np.cos(theta), np.sin(theta)
        a = np.empty((n, 2))
        a[:, 0], a[:, 1] = cs, sn
        b = np.empty((n, 2))
        b[:, 0], b[:, 1] = -sn, cs
        cos_d = np.multiply.outer(cs, cs) + np.multiply.outer(sn, sn)  # cos(theta_j - theta_k)
        mass = (m.h**2) * m.weight_matrix * cos_d
        mass[np.diag_indices(n)] += m.rot_inertia
        x = np.empty((n + 1, 2))
        x[0] = m.base_position
        np.cumsum(m.h * a, axis=0, out=x[1:])
        x[1:] += x[0]
        c = 0.5 * (x[:-1] + x[1:])
        # centre velocities and centripetal accelerations (chain.centre_velocities / ...accelerations)
        bw = m.h * b * omega[:, None]
        aw = -m.h * a * (omega**2)[:, None]
        v = 0.5 * bw
        v[1:] += np.cumsum(bw[:-1], axis=0)
        acc = 0.5 * aw
        acc[1:] += np.cumsum(aw[:-1], axis=0)
        f = -m.mass[:, None] * acc
        jac_w = m.damping * mass
        jac_q = m.stiffness_matrix.copy()
        pen = 0.0
        if m.drag_normal > 0 or m.drag_tangential > 0:
            fd, gn, gt = drag_forces(m, a, b, v)
            f += fd
            # isotropic bound of the drag derivative (exact form not needed in the Newton matrix)
            jac_w += (m.h**2) * chain.weighted_gram(np.maximum(gn, gt)) * cos_d
        if frame is not None:
            cl = contact_forces(m, frame, c, v)
            f += cl.forces
            kc, dc = contact_matrices(m, theta, frame, cl)
            jac_q += kc
            jac_w += dc
            pen = float(max(cl.penetration.max(), 0.0))
        tail = np.zeros_like(f)
        np.cumsum(f[:0:-1], axis=0, out=tail[-2::-1])
        tail += 0.5 * f
        if loads.node_forces is not None:
            fn_ = np.asarray(loads.node_forces, dtype=float)
            tail += np.cumsum(fn_[:0:-1], axis=0)[::-1]
        q = m.h * np.sum(b * tail, axis=1)
        jac_q[np.diag_indices(n)] += m.h * np.sum(a * tail, axis=1)
        mom = m.joint_ei * m.joint_curvature(theta)
        if loads.couple is not None:
            mom = mom + loads.couple
        if loads.feedback is not None:
            u, du = loads.feedback.couple_and_jacobian(theta, nodes=x, normals=b)
            mom = mom + u
            jac_q += du
            jac_q[:-1] -= du[1:]
        q -= mom
        q[:-1] += mom[1:]
        if m.damping > 0:
            q -= m.damping * (mass @ omega)
        return _Eval(q=q, mass=mass, jac_w=jac_w, jac_q=jac_q, penetration=pen)

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
        """Advance by ``duration`` (s) with adaptive steps: start from ``dt_try`` (default: the whole
        duration), halve on Newton failure or when the accuracy guard trips, double after two
        consecutive successes. ``info["dt_next"]`` is the step to try next time."""
        if not (np.isfinite(duration) and duration > 0):
            raise InvalidParameterError(f"dt/duration must be finite and > 0, got {duration!r}")
        info = {"iterations": 0, "substeps": 0, "penetration": 0.0}
        dt = duration if dt_try is None else min(float(dt_try), duration)
        dt_min = duration / 2.0**self.options.max_halvings
        t_end = state.t + duration
        ok_run = 0
        while t_end - state.t > 1e-12 * max(1.0, abs(t_end)):
            h = min(dt, t_end - state.t)
            new = self._try_step(state, h, loads, info)
            if new is None:
                if h <= dt_min * (1 + 1e-9):
                    raise StepFailedError(f"Newton failed to converge at t={state.t:.6g} s even with dt={h:.3g} s")
                dt = 0.5 * h
                ok_run = 0
                continue
            state = new
            ok_run += 1
            if ok_run >= 2 and h >= dt * (1 - 1e-9):
                dt = min(2.0 * dt, duration)
                ok_run = 0
        info["dt_next"] = dt
        return state, info

    def _try_step(self, state: RodState, dt: float, loads: RodLoads, info: dict) -> RodState | None:
        m, opt = self.model, self.options
        th0, w0 = state.theta, state.omega
        frame = None
        if self.obstacle is not None:
            c0 = chain.centres(m, th0 + 0.5 * dt * w0)
            frame = contact_frame(m, self.obstacle, c0, opt.contact_margin + 2.0 * dt * np.abs(w0).max() * m.length)
        midpoint = opt.method == "midpoint"
        cw, cq = (0.5, 0.25 * dt) if midpoint else (1.0, dt)
        w1 = w0.copy()
        for it in range(1, opt.max_iter + 1):
            if midpoint:
                w_ = 0.5 * (w0 + w1)
                th_ = th0 + 0.5 * dt * w_
            else:
                w_, th_ = w1, th0 + dt * w1
            ev = self._evaluate(th_, w_, loads, frame)
            res = ev.mass @ (w1 - w0) - dt * ev.q
            jac = ev.mass + dt * cw * ev.jac_w + dt * cq * ev.jac_q
            dw = np.linalg.solve(jac, -res)
            if not np.all(np.isfinite(dw)):
                info["iterations"] += it
                return None
            w1 = w1 + dw
            if dt * np.abs(dw).max() <= opt.tol * (1.0 + np.abs(th_).max()):
                info["iterations"] += it
                th1 = th0 + (0.5 * dt * (w0 + w1) if midpoint else dt * w1)
                if np.abs(th1 - th0).max() > opt.max_angle_step:
                    return None  # accuracy guard: too large a rotation in one step
                info["substeps"] += 1
                info["penetration"] = max(info["penetration"], ev.penetration)
                return RodState(t=state.t + dt, theta=th1, omega=w1)
        info["iterations"] += opt.max_iter
        return None
