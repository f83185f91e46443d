"""Contact between the rod and a movable object, with every derivative the implicit step needs.

The penalty contact of :mod:`contgrasp_core.rod.loads` (paper Remark 2, Sec. V-C) extended to an
object that moves (:mod:`contgrasp_core.rod.body`): the step's tangent-line model rides with the
object, penetration rate and friction use the rod's velocity relative to the object, and the
object receives the opposite force at the same point (momentum balances). Also stick-slip
friction (anchors, Coulomb cone, return map). :func:`body_coupling` returns the rod's generalised
force, the object's wrench and their exact derivatives; with ``body=None`` the same contact
against a fixed object. docs/rod.md, "A movable object".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.rod import chain
from contgrasp_core.rod.body import RigidBody, rotation
from contgrasp_core.rod.loads import ContactFrame
from contgrasp_core.rod.model import RodModel

__all__ = ["BodyCoupling", "body_coupling"]

Array = NDArray[np.float64]

# columns of the per-contact partial derivatives: centre c (2), centre velocity v (2),
# object translation (2) and rotation (1), object velocity (2) and angular velocity (1)
_C, _V, _Q, _W = slice(0, 2), slice(2, 4), slice(4, 7), slice(7, 10)


@dataclass(frozen=True)
class BodyCoupling:
    """Rod generalised force ``rod`` (N,) and object wrench ``wrench`` (3,) with their
    derivatives: ``rod_theta``, ``rod_omega`` (N, N), ``rod_q``, ``rod_v`` (N, 3),
    ``wrench_theta``, ``wrench_omega`` (3, N), ``wrench_q``, ``wrench_v`` (3, 3);
    ``penetration`` the deepest surface penetration (m, >= 0); ``anchors`` (N, 2) the stick-slip
    anchors after a step ending here (NaN: no contact; None with regularised friction)."""

    rod: Array
    wrench: Array
    rod_theta: Array
    rod_omega: Array
    rod_q: Array
    rod_v: Array
    wrench_theta: Array
    wrench_omega: Array
    wrench_q: Array
    wrench_v: Array
    penetration: float
    anchors: Array | None = None


def _perp(u: Array) -> Array:
    """``R(pi/2) u`` row-wise."""
    return np.stack([-u[..., 1], u[..., 0]], axis=-1)


def body_coupling(model: RodModel, body: RigidBody | None, frame: ContactFrame | None, theta: Array,
                  omega: Array, q: Array, v: Array, applied: Array | None = None,
                  anchors: Array | None = None) -> BodyCoupling:
    """Contact forces between the rod at (``theta``, ``omega``) and the object at displacement
    ``q`` with velocity ``v`` (``frame`` in the object's start-pose frame, None = no centre near
    it), plus the ``applied`` wrench (3,) and the spring-damper on the object (module docstring).
    ``body=None``: a fixed object (``q``, ``v`` zero). ``anchors`` (N, 2): the stick-slip anchors
    of the step (every frame row has one; needed with ``friction_model == "stick"``)."""
    n = model.n_elements
    stick = model.friction > 0 and model.friction_model == "stick"
    if stick and frame is not None and (anchors is None or np.isnan(anchors[frame.rows]).any()):
        raise ValueError("stick-slip friction needs an anchor for every contact row")  # (a caller's bug)
    spring_q = np.zeros((3, 3)) if body is None else -np.diag(body.stiffness)
    spring_v = np.zeros((3, 3)) if body is None else -np.diag(body.damping)
    wrench = np.zeros(3) if body is None else body.support_wrench(q, v)
    if applied is not None:
        wrench = wrench + np.asarray(applied, dtype=float)
    if frame is None:
        return BodyCoupling(rod=np.zeros(n), wrench=wrench, rod_theta=np.zeros((n, n)), rod_omega=np.zeros((n, n)),
                            rod_q=np.zeros((n, 3)), rod_v=np.zeros((n, 3)), wrench_theta=np.zeros((3, n)),
                            wrench_omega=np.zeros((3, n)), wrench_q=spring_q, wrench_v=spring_v, penetration=0.0,
                            anchors=np.full((n, 2), np.nan) if stick else None)
    r, h = frame.rows, model.h
    a, b = chain.frames(theta)
    weights = chain.lower_weights(n)[r]  # w_ij of the contact rows (nr, N)
    g = h * weights[:, None, :] * b.T[None]  # dc_i/dtheta (nr, 2, N)
    ga = h * weights[:, None, :] * a.T[None]
    dv_dtheta = -ga * omega  # dv_i/dtheta (nr, 2, N)
    c = chain.centres(model, theta)[r]
    vel = chain.centre_velocities(model, theta, omega)[r]
    centroid = np.zeros(2) if body is None else np.asarray(body.centroid)
    rot = rotation(q[2])
    normal = frame.normal @ rot.T
    tangent = _perp(normal)
    foot = centroid + q[:2] + (frame.foot - centroid) @ rot.T
    rel = c - centroid - q[:2]
    slip = vel - v[:2] - v[2] * _perp(rel)  # rod velocity relative to the object's material point
    dot = lambda x, y: np.sum(x * y, axis=-1)  # noqa: E731 (row-wise dot product)
    pen = model.r_centres[r] - dot(normal, c - foot)
    pen_rate = -dot(normal, slip)
    vt = dot(tangent, slip)
    nr = len(r)
    d_pen, d_rate, d_vt = np.zeros((nr, 10)), np.zeros((nr, 10)), np.zeros((nr, 10))
    d_pen[:, _C], d_pen[:, 4:6], d_pen[:, 6] = -normal, normal, -dot(tangent, rel)
    d_rate[:, _C], d_rate[:, _V], d_rate[:, 4:6] = -v[2] * tangent, -normal, v[2] * tangent
    d_rate[:, 6], d_rate[:, 7:9], d_rate[:, 9] = -dot(tangent, slip), normal, -dot(tangent, rel)
    d_vt[:, _C], d_vt[:, _V], d_vt[:, 4:6] = -v[2] * normal, tangent, v[2] * normal
    d_vt[:, 6], d_vt[:, 7:9], d_vt[:, 9] = -dot(normal, slip), -tangent, -dot(normal, rel)
    fn = h * (model.contact_stiffness * pen + model.contact_damping * pen_rate)
    active = (pen > 0) & (fn > 0)
    fn = np.where(active, fn, 0.0)
    d_fn = np.where(active[:, None], h * (model.contact_stiffness * d_pen + model.contact_damping * d_rate), 0.0)
    new_anchors = None
    if stick:  # tangential force -ft t: elastic to the anchor inside the cone, Coulomb's at its edge
        assert anchors is not None
        anchor = centroid + q[:2] + (anchors[r] - centroid) @ rot.T
        e = dot(tangent, c - anchor)
        d_e = np.zeros((nr, 10))
        d_e[:, _C], d_e[:, 4:6], d_e[:, 6] = tangent, -tangent, -dot(normal, rel)
        trial = h * (model.contact_stiffness * e + model.contact_damping * vt)
        d_trial = h * (model.contact_stiffness * d_e + model.contact_damping * d_vt)
        limit = model.friction * fn
        slipping = np.abs(trial) > limit
        sign = np.sign(trial)
        ft = np.where(active, np.where(slipping, sign * limit, trial), 0.0)
        d_ft = np.where(active[:, None], np.where(slipping[:, None], (sign * model.friction)[:, None] * d_fn, d_trial), 0.0)
        f = fn[:, None] * normal - ft[:, None] * tangent
        d_f = d_fn[:, None, :] * normal[:, :, None] - d_ft[:, None, :] * tangent[:, :, None]
        d_f[:, :, 6] += fn[:, None] * tangent + ft[:, None] * normal  # dn/dpsi = t, dt/dpsi = -n
        # return map: a slipping contact's anchor to the cone's edge; an open contact forgets it
        e_cone = np.where(slipping, sign * limit / (h * model.contact_stiffness), e)
        moved = anchor + (e - e_cone)[:, None] * tangent
        new_anchors = np.full((n, 2), np.nan)
        new_anchors[r] = np.where(active[:, None], centroid + (moved - centroid - q[:2]) @ rot, np.nan)
    else:
        ratio, d_ratio = np.zeros(nr), np.zeros((nr, 10))
        if model.friction > 0:
            x = vt / model.friction_velocity
            ratio = model.friction * np.tanh(x)
            d_ratio = (model.friction / model.friction_velocity * (1.0 - np.tanh(x) ** 2))[:, None] * d_vt
        push = normal - ratio[:, None] * tangent
        d_push = -d_ratio[:, None, :] * tangent[:, :, None]
        d_push[:, :, 6] += tangent + ratio[:, None] * normal  # dn/dpsi = t, dt/dpsi = -n
        f = fn[:, None] * push  # on the rod (nr, 2)
        d_f = d_fn[:, None, :] * push[:, :, None] + fn[:, None, None] * d_push  # (nr, 2, 10)
    # the object's wrench from -f_i at c_i: force -f, torque -(rel x f)
    d_w = np.empty((nr, 3, 10))
    d_w[:, :2] = -d_f
    d_w[:, 2] = -(rel[:, 0, None] * d_f[:, 1] - rel[:, 1, None] * d_f[:, 0])
    d_w[:, 2, 0] -= f[:, 1]
    d_w[:, 2, 1] += f[:, 0]
    d_w[:, 2, 4] += f[:, 1]
    d_w[:, 2, 5] -= f[:, 0]

    def wrt_rod(d: Array) -> tuple[Array, Array]:  # per-row partials -> d/dtheta, d/domega (nr, k, N)
        return d[:, :, _C] @ g + d[:, :, _V] @ dv_dtheta, d[:, :, _V] @ g

    f_theta, f_omega = wrt_rod(d_f)
    w_theta, w_omega = wrt_rod(d_w)
    gt = g.reshape(2 * nr, n).T  # G^T: the generalised force of the rows' centre forces (N, 2 nr)
    rod_theta = gt @ f_theta.reshape(2 * nr, n)
    rod_theta[np.diag_indices(n)] -= ga.reshape(2 * nr, n).T @ f.reshape(-1)  # b_j turns with theta_j: d b_j = -a_j
    torque = -(rel[:, 0] * f[:, 1] - rel[:, 1] * f[:, 0])
    return BodyCoupling(
        rod=gt @ f.reshape(-1),
        wrench=wrench + np.array([-f[:, 0].sum(), -f[:, 1].sum(), torque.sum()]),
        rod_theta=rod_theta,
        rod_omega=gt @ f_omega.reshape(2 * nr, n),
        rod_q=gt @ d_f[:, :, _Q].reshape(2 * nr, 3),
        rod_v=gt @ d_f[:, :, _W].reshape(2 * nr, 3),
        wrench_theta=w_theta.sum(axis=0),
        wrench_omega=w_omega.sum(axis=0),
        wrench_q=spring_q + d_w[:, :, _Q].sum(axis=0),
        wrench_v=spring_v + d_w[:, :, _W].sum(axis=0),
        penetration=float(max(pen.max(), 0.0)),
        anchors=new_anchors,
    )
