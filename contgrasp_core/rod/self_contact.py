"""Contact of the arm with itself: parts that are not neighbours repel (docs/rod.md, "Self-contact").

Beyond the paper, whose arm never meets itself: a coil round a small object presses its turns
together. Each element centre ``c_i`` is tested against the polyline through the centres; a
segment ``(l, l+1)`` whose closest point (the foot, parameter ``t``) lies farther along the arm
than ``pi (r_i + r_foot) / 2`` is another part of the arm (a section bent to its own radius turns
by half a turn over that arclength, so nearer sections meet only by bending, not by contact).
The pair's surfaces overlap by ``p = r_i + r_foot - n . (c_i - foot)`` with the normal ``n``
frozen over the step, as the object's tangent line is (:mod:`.loads`). The same penalty law as
the object's acts on both: ``F = (h/2) max(k p + c p', 0)`` pushes ``c_i`` along ``n`` and the
foot's centres ``l``, ``l+1`` back with weights ``1 - t``, ``t``. Both parts of a pair test each
other, so each sees half the law and two pressed runs feel exactly ``k p`` per unit length.
:func:`self_contact_load` gives the generalised force and its exact derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.rod import _kernels, chain
from contgrasp_core.rod.model import RodModel

__all__ = ["SelfContactFrame", "SelfContactLoad", "SelfGap", "self_contact_frame", "missed_pairs", "self_contact_load",
           "self_contact_energy", "self_gap"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SelfContactFrame:
    """Pairs frozen over one step: centre ``centre`` (P,) against the centre polyline's segment
    ``(segment, segment + 1)`` (P,) at parameter ``t`` (P,), along ``normal`` (P, 2) (foot to centre)."""

    centre: NDArray[np.int64]
    segment: NDArray[np.int64]
    t: Array
    normal: Array


@dataclass(frozen=True)
class SelfContactLoad:
    """Generalised force ``q`` (N,) of the self-contact and its derivatives ``q_theta`` =
    ``dq/dtheta``, ``q_omega`` = ``dq/domega`` (N, N); the ``forces`` on the element centres (N, 2);
    ``overlap`` the deepest surface overlap (m, >= 0)."""

    q: Array
    forces: Array
    q_theta: Array
    q_omega: Array
    overlap: float


@dataclass(frozen=True)
class SelfGap:
    """The smallest surface gap between parts of the arm that are not neighbours: ``gap`` (m;
    negative: they overlap; +inf when no two parts are near), ``ratio`` the overlap over the
    thinner part's radius (0 without overlap), at arclengths ``s`` and ``s_other`` (m); +inf
    beyond the search's margin."""

    gap: float
    ratio: float
    s: float
    s_other: float


_Geometry = tuple[Array, Array, Array, Array, NDArray[np.bool_]]
_Pairs = tuple[NDArray[np.int64], NDArray[np.int64], Array, Array, Array, Array]


def _segment_geometry(model: RodModel, c: Array, i: NDArray[np.int64], seg: NDArray[np.int64]) -> _Geometry:
    """For centres ``i`` and segments ``seg`` (paired arrays): foot parameter, foot, distance, the
    radius at the foot and whether the pair is near along the arm (neighbours)."""
    p0, p1 = c[seg], c[seg + 1]
    e = p1 - p0
    t = np.clip(np.sum((c[i] - p0) * e, axis=1) / np.sum(e * e, axis=1), 0.0, 1.0)
    foot = p0 + t[:, None] * e
    dist = np.hypot(*(c[i] - foot).T)
    r = model.r_centres
    r_foot = (1.0 - t) * r[seg] + t * r[seg + 1]
    s_foot = model.s_centres[seg] + t * model.h
    near = np.abs(model.s_centres[i] - s_foot) <= 0.5 * np.pi * (r[i] + r_foot)
    return t, foot, dist, r_foot, near


def _pairs(model: RodModel, c: Array, margin: float) -> _Pairs | None:
    """Candidate (centre, segment) pairs whose surfaces are within ``margin``, then kept where the
    segment is the closest of its neighbours along the arm (one pair per meeting) and not near."""
    n, h, r = model.n_elements, model.h, model.r_centres
    if _kernels.ENABLED:  # the same search in one compiled loop
        i, seg, t, dist, r_foot = _kernels.self_contact_pairs(_kernels.f64(c), model.s_centres, r, h, float(margin))
        foot = (1.0 - t)[:, None] * c[seg] + t[:, None] * c[seg + 1]
        return i, seg, t, foot, dist, r_foot
    from scipy.spatial import cKDTree  # (the reference path only: the light ROS nodes import this module without scipy)

    close = cKDTree(c).query_pairs(2.0 * float(r.max()) + margin + h, output_type="ndarray")
    if close.size:  # keep the pairs near enough for their radii whose nearby feet are not all neighbours
        i, j = close[:, 0], close[:, 1]
        taper = abs(model.radius_tip - model.radius_base) / model.length
        neighbours = np.abs(model.s_centres[i] - model.s_centres[j]) + h < 0.5 * np.pi * (r[i] + r[j] - 2 * taper * h)
        far = np.hypot(*(c[i] - c[j]).T) > r[i] + r[j] + 2 * taper * h + margin + h
        close = close[~(neighbours | far)]
    if close.size == 0:
        return None
    both = np.concatenate([close, close[:, ::-1]])  # (centre, other centre) both ways
    i = np.repeat(both[:, 0], 2)
    seg = np.stack([both[:, 1] - 1, both[:, 1]], axis=1).ravel()  # the two segments at the other centre
    ok = (seg >= 0) & (seg <= n - 2)
    key = np.unique(i[ok] * n + seg[ok])
    i, seg = key // n, key % n
    t, foot, dist, r_foot, near = _segment_geometry(model, c, i, seg)
    hit = ~near & (dist - r[i] - r_foot < margin)
    if not hit.any():
        return None
    i, seg, t, foot, dist, r_foot = i[hit], seg[hit], t[hit], foot[hit], dist[hit], r_foot[hit]
    prev = np.full(len(i), np.inf)
    nxt = np.full(len(i), np.inf)
    has_prev, has_next = seg > 0, seg < n - 2
    prev[has_prev] = _segment_geometry(model, c, i[has_prev], seg[has_prev] - 1)[2]
    nxt[has_next] = _segment_geometry(model, c, i[has_next], seg[has_next] + 1)[2]
    keep = (dist <= prev) & (dist < nxt)  # the closest segment of its run along the arm: one pair per meeting
    return i[keep], seg[keep], t[keep], foot[keep], dist[keep], r_foot[keep]


def self_contact_frame(model: RodModel, c: Array, margin: float) -> SelfContactFrame | None:
    """The pairs of centres ``c`` (N, 2) and segments whose surfaces are within ``margin`` (m)."""
    found = _pairs(model, c, margin)
    if found is None or found[0].size == 0:
        return None
    i, seg, t = found[:3]
    return SelfContactFrame(centre=i.astype(np.int64), segment=seg.astype(np.int64), t=t, normal=_normals(c, i, seg, t))


def _normals(c: Array, i: NDArray[np.int64], seg: NDArray[np.int64], t: Array) -> Array:
    """Unit normals from the feet at ``t`` on the segments to the centres ``i`` (the segment's
    normal for a centre on it)."""
    e = c[seg + 1] - c[seg]
    d = c[i] - (c[seg] + t[:, None] * e)
    dist = np.hypot(*d.T)
    normal = np.where((dist > 0)[:, None], d / np.where(dist > 0, dist, 1.0)[:, None], np.stack([-e[:, 1], e[:, 0]], axis=1))
    return normal / np.hypot(*normal.T)[:, None]


def missed_pairs(model: RodModel, frame: SelfContactFrame | None, c_start: Array,
                 c_end: Array) -> SelfContactFrame | None:
    """``frame`` with the pairs that overlap at the end of a step (centres ``c_end``) but were not
    in it (the step moved them faster than its margin foresaw), their normals taken where the
    step started (``c_start``: from the side they came from); None when none was missed."""
    found = _pairs(model, c_end, 0.0)
    if found is None or found[0].size == 0:
        return None
    i, seg, t = found[:3]
    n = model.n_elements
    if frame is not None:  # (a framed pair whose foot moved on to the next segment is the same meeting)
        framed = frame.centre * n + frame.segment
        new = ~(np.isin(i * n + seg, framed) | np.isin(i * n + seg - 1, framed) | np.isin(i * n + seg + 1, framed))
        i, seg, t = i[new], seg[new], t[new]
    if i.size == 0:
        return None
    normal = _normals(c_start, i, seg, t)
    if frame is None:
        return SelfContactFrame(centre=i.astype(np.int64), segment=seg.astype(np.int64), t=t, normal=normal)
    return SelfContactFrame(centre=np.concatenate([frame.centre, i]), segment=np.concatenate([frame.segment, seg]),
                            t=np.concatenate([frame.t, t]), normal=np.concatenate([frame.normal, normal]))


def self_contact_load(model: RodModel, frame: SelfContactFrame, theta: Array, omega: Array) -> SelfContactLoad | None:
    """The self-contact's generalised force at (``theta``, ``omega``) with the step's frozen
    ``frame`` and its exact derivatives (module docstring); None when no pair presses."""
    h = model.h
    i, seg, t, nrm = frame.centre, frame.segment, frame.t, frame.normal
    a, b, x = chain.frames_and_nodes(model, theta)
    c = 0.5 * (x[:-1] + x[1:])
    foot = (1.0 - t)[:, None] * c[seg] + t[:, None] * c[seg + 1]
    r = model.r_centres
    pen = r[i] + (1.0 - t) * r[seg] + t * r[seg + 1] - np.sum(nrm * (c[i] - foot), axis=1)
    if not (pen > 0).any():
        return None
    w = chain.lower_weights(model.n_elements)
    weight = h * (w[i] - (1.0 - t)[:, None] * w[seg] - t[:, None] * w[seg + 1])  # d(c_i - foot)/dtheta along b_j
    gn = weight * (nrm @ b.T)  # n . d(c_i - foot)/dtheta_j (P, N)
    gan = weight * (nrm @ a.T)
    rate = -(gn @ omega)
    k, cd = 0.5 * h * model.contact_stiffness, 0.5 * h * model.contact_damping
    force = k * pen + cd * rate
    active = (pen > 0) & (force > 0)
    if not active.any():
        return None
    force = np.where(active, force, 0.0)
    gn_a = gn[active]
    f_theta = -k * gn_a + cd * gan[active] * omega
    q_theta = gn_a.T @ f_theta
    q_theta[np.diag_indices_from(q_theta)] -= gan.T @ force
    push = force[:, None] * nrm
    forces = np.zeros_like(c)
    np.add.at(forces, i, push)
    np.add.at(forces, seg, -(1.0 - t)[:, None] * push)
    np.add.at(forces, seg + 1, -t[:, None] * push)
    return SelfContactLoad(q=gn.T @ force, forces=forces, q_theta=q_theta, q_omega=-cd * (gn_a.T @ gn_a),
                           overlap=float(pen.max()))


def self_contact_energy(model: RodModel, theta: Array) -> float:
    """The penalty's stored energy ``sum (h/2) k p^2 / 2`` over the pairs that overlap at ``theta``
    (J), the potential of the law's elastic part with the pairs' current normals."""
    found = _pairs(model, chain.centres(model, theta), 0.0)
    if found is None:
        return 0.0
    i, _, _, _, dist, r_foot = found
    pen = np.maximum(model.r_centres[i] + r_foot - dist, 0.0)
    return float(0.25 * model.h * model.contact_stiffness * np.sum(pen**2))


def self_gap(model: RodModel, theta: Array, margin: float | None = None) -> SelfGap:
    """The smallest surface gap between non-neighbouring parts of the arm at angles ``theta``
    (the measure of "passed through itself"; :class:`SelfGap`), searched up to ``margin`` (m;
    default twice the largest radius; 0: overlaps only)."""
    found = _pairs(model, chain.centres(model, theta), 2.0 * float(model.r_centres.max()) if margin is None else margin)
    if found is None or found[0].size == 0:
        return SelfGap(gap=np.inf, ratio=0.0, s=np.nan, s_other=np.nan)
    i, seg, t, _, dist, r_foot = found
    gaps = dist - model.r_centres[i] - r_foot
    k = int(np.argmin(gaps))
    thinner = min(float(model.r_centres[i[k]]), float(r_foot[k]))
    return SelfGap(gap=float(gaps[k]), ratio=max(-float(gaps[k]), 0.0) / thinner, s=float(model.s_centres[i[k]]),
                   s_other=float(model.s_centres[seg[k]] + t[k] * model.h))
