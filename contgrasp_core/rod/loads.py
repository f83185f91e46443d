"""External loads on the rod's element centres and their linearisations (paper eq. (17), the rod dynamics).

Fluid drag (Appendix IV; normal and tangential, quadratic in the velocity, over the local
diameter) and penalty contact with a fixed object (paper Remark 2, Sec. V-C: the surface's
penetration against the step's frozen tangent line, ``max(k p + c dp/dt, 0)`` per unit length,
never adhesive, optional regularised Coulomb friction). Each function returns the centre forces
(N, 2) and their derivatives for the integrator (:func:`contgrasp_core.rod.chain.gram_form`).
docs/rod.md, "Model".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contgrasp_core.rod.chain import outer_entries
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.obstacle import Obstacle

__all__ = ["ContactFrame", "ContactLoad", "contact_frame", "drag_forces", "contact_forces", "contact_tensors"]

_TURN = np.array([-1.0, 1.0])  # (n_y, n_x) * _TURN = (-n_y, n_x): the normal turned by +90 degrees


@dataclass(frozen=True)
class ContactFrame:
    """Tangent-line model of the object near each centre, frozen over one step.

    ``rows`` indices of centres considered (within ``margin`` of contact); ``foot``, ``normal``
    (outward), ``tangent`` (n, 2) for those rows; ``anchors`` (N, 2) the stick-slip anchors of
    the step (stick-slip friction only, :mod:`contgrasp_core.rod.coupling`).
    """

    rows: np.ndarray
    foot: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    anchors: np.ndarray | None = None


def contact_frame(model: RodModel, obstacle: Obstacle | None, c: np.ndarray, margin: float) -> ContactFrame | None:
    """Project the centres ``c`` (N, 2) and keep those whose surface is within ``margin`` (m)."""
    if obstacle is None:
        return None
    pr = obstacle.project(c)
    rows = np.flatnonzero(pr.signed_distance - model.r_centres < margin)
    if rows.size == 0:
        return None
    n = pr.normal_out[rows]
    return ContactFrame(rows=rows, foot=pr.foot[rows], normal=n, tangent=n[:, ::-1] * _TURN)


def drag_forces(model: RodModel, a: np.ndarray, b: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadratic drag on the centres: forces (N, 2) and the derivative coefficients
    ``(g_n, g_t)`` with ``d f/d v = -(g_n b b^T + g_t a a^T)`` per centre."""
    vn = np.sum(v * b, axis=1)
    vt = np.sum(v * a, axis=1)
    dl = 2.0 * model.r_centres * model.h
    fn = -model.drag_normal * dl * np.abs(vn) * vn
    ft = -model.drag_tangential * dl * np.abs(vt) * vt
    f = fn[:, None] * b + ft[:, None] * a
    return f, 2.0 * model.drag_normal * dl * np.abs(vn), 2.0 * model.drag_tangential * dl * np.abs(vt)


@dataclass(frozen=True)
class ContactLoad:
    """Contact result for one evaluation: ``forces`` (N, 2); ``penetration`` (n,) on the frame
    rows; ``stiffness``/``damping`` (n,) force derivatives along the normal (active rows only
    non-zero); ``friction_damping`` (n,) derivative of the friction force along the tangent;
    ``friction_ratio`` (n,) ``mu tanh(v_t / v_eps)``, the friction force per unit normal force."""

    forces: np.ndarray
    penetration: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    friction_damping: np.ndarray
    friction_ratio: np.ndarray


def contact_forces(model: RodModel, frame: ContactFrame, c: np.ndarray, v: np.ndarray) -> ContactLoad:
    """Penalty contact forces on the centres for positions ``c`` and velocities ``v`` (N, 2)."""
    r = frame.rows
    pen = model.r_centres[r] - np.sum((c[r] - frame.foot) * frame.normal, axis=1)
    pen_rate = -np.sum(v[r] * frame.normal, axis=1)
    fn = model.h * (model.contact_stiffness * pen + model.contact_damping * pen_rate)
    active = (pen > 0) & (fn > 0)
    fn = np.where(active, fn, 0.0)
    forces = np.zeros_like(c)
    forces[r] = fn[:, None] * frame.normal
    fr_damp, fr_ratio = np.zeros_like(fn), np.zeros_like(fn)
    if model.friction > 0:
        vt = np.sum(v[r] * frame.tangent, axis=1)
        x = vt / model.friction_velocity
        fr_ratio = model.friction * np.tanh(x)
        forces[r] -= (fr_ratio * fn)[:, None] * frame.tangent
        fr_damp = model.friction * fn / model.friction_velocity / np.cosh(x) ** 2
    k = np.where(active, model.h * model.contact_stiffness, 0.0)
    d = np.where(active, model.h * model.contact_damping, 0.0)
    return ContactLoad(forces=forces, penetration=pen, stiffness=k, damping=d, friction_damping=fr_damp,
                       friction_ratio=np.where(active, fr_ratio, 0.0))


def contact_tensors(model: RodModel, frame: ContactFrame, load: ContactLoad) -> tuple[np.ndarray, np.ndarray]:
    """Per-centre contact stiffness ``-df_i/dc_i`` and damping ``-df_i/dv_i`` tensors as
    ``xx, xy, yx, yy`` entries, each (4, N) (zero off contact). The frame is frozen over the
    step, so the force ``f = f_n (n - mu tanh(v_t/v_eps) t)`` depends on the centre positions and
    velocities only: ``-df/dc = k (n - mu tanh t) n^T``, ``-df/dv = c (n - mu tanh t) n^T +
    friction_damping t t^T``. Assembled with :func:`contgrasp_core.rod.chain.gram_form`."""
    n = model.n_elements
    k, d, fr, ratio = (np.zeros(n) for _ in range(4))
    r = frame.rows
    k[r], d[r], fr[r], ratio[r] = load.stiffness, load.damping, load.friction_damping, load.friction_ratio
    nrm, tng = np.zeros((n, 2)), np.zeros((n, 2))
    nrm[r], tng[r] = frame.normal, frame.tangent
    push = nrm - ratio[:, None] * tng  # direction of the force per unit normal force
    return outer_entries(k, push, nrm), outer_entries(d, push, nrm) + outer_entries(fr, tng, tng)
