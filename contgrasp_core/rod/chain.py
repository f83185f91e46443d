"""Reduced-coordinate kinematics of the discrete rod (eq. (1), arm kinematics; eq. (18), clamped base).

Generalised coordinates are the element angles ``theta`` (N,). With ``a_j = (cos, sin)(theta_j)``
and ``b_j = R(pi/2) a_j``, the nodes are ``x_k = r0 + h sum_{j<k} a_j`` and the element centres
``c_i = r0 + h (sum_{j<i} a_j + a_i / 2)``, so ``r(0) = r0`` and inextensibility/unshearability
hold exactly. The centre Jacobian is ``dc_i/dtheta_j = h w_ij b_j`` with ``w_ij = 1`` for
``j < i``, ``1/2`` for ``j = i``, 0 otherwise. All maps are O(N) cumulative sums except the
mass matrix and the force derivatives (O(N^2), :func:`gram_form`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from contgrasp_core.arm import ArmShape
from contgrasp_core.rod import _kernels
from contgrasp_core.rod.model import RodModel

__all__ = [
    "frames",
    "nodes",
    "frames_and_nodes",
    "centres",
    "node_angles",
    "element_angles",
    "arm_shape",
    "centre_velocities",
    "centripetal_accelerations",
    "generalized_from_centre_forces",
    "generalized_from_node_forces",
    "mass_matrix",
    "weight_matrix",
    "lower_weights",
    "gram_form",
    "outer_entries",
]


def frames(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent ``a`` and normal ``b`` of every element, each (N, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c, s], axis=1), np.stack([-s, c], axis=1)


def nodes(model: RodModel, theta: np.ndarray, tangents: np.ndarray | None = None) -> np.ndarray:
    """Node positions ``x_k``, k = 0..N (N+1, 2); ``tangents`` (N, 2) may be passed when
    already computed (:func:`frames`)."""
    a = frames(theta)[0] if tangents is None else tangents
    x = np.empty((len(theta) + 1, 2))
    x[0] = model.base_position
    np.cumsum(model.h * a, axis=0, out=x[1:])
    x[1:] += x[0]
    return x


def frames_and_nodes(model: RodModel, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`frames` and :func:`nodes` (``a``, ``b``, ``x``) in one compiled loop
    (:func:`contgrasp_core.rod._kernels.frames_nodes`, the same values to the bit) unless the
    kernels are disabled. For the rod engine (a process that imports numba anyway)."""
    if _kernels.ENABLED:
        return _kernels.frames_nodes(_kernels.f64(theta), model.h, model.base)
    a, b = frames(theta)
    return a, b, nodes(model, theta, a)


def centres(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Element centres, the midpoints of consecutive nodes (N, 2) (:func:`frames_and_nodes`'s)."""
    x = frames_and_nodes(model, theta)[2]
    return 0.5 * (x[:-1] + x[1:])


def node_angles(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Tangent angle at the nodes: the clamp angle at the base, the mean of adjacent elements
    inside, the last element's angle at the tip (N+1,)."""
    out = np.empty(len(theta) + 1)
    out[0] = model.base_angle
    out[1:-1] = 0.5 * (theta[:-1] + theta[1:])
    out[-1] = theta[-1]
    return out


def element_angles(node_theta: np.ndarray) -> np.ndarray:
    """The element angles (N,) whose :func:`node_angles` are ``node_theta`` (N+1,): the last
    element's is the tip's, and each node inside is the mean of its two elements."""
    out = np.empty(len(node_theta) - 1)
    out[-1] = node_theta[-1]
    for k in range(len(out) - 1, 0, -1):
        out[k - 1] = 2.0 * node_theta[k] - out[k]
    return out


def arm_shape(model: RodModel, theta: np.ndarray, node_positions: np.ndarray | None = None) -> ArmShape:
    """The rod's centreline at its N+1 nodes (arclengths ``s_nodes``, :func:`nodes`,
    :func:`node_angles`), the arm shape :func:`contgrasp_core.contact.sense` senses.
    ``node_positions`` (N+1, 2) may be passed when already computed."""
    x = nodes(model, theta) if node_positions is None else node_positions
    return ArmShape(s=model.s_nodes, r=x, theta=node_angles(model, theta))


def _prefix_excl(v: np.ndarray) -> np.ndarray:
    """Exclusive prefix sums along axis 0."""
    out = np.zeros_like(v)
    np.cumsum(v[:-1], axis=0, out=out[1:])
    return out


def _suffix_excl(v: np.ndarray) -> np.ndarray:
    """Exclusive suffix sums along axis 0: ``sum_{i>j} v_i``."""
    out = np.zeros_like(v)
    np.cumsum(v[:0:-1], axis=0, out=out[-2::-1])
    return out


def centre_velocities(model: RodModel, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """``v_i = h sum_j w_ij b_j omega_j`` (N, 2)."""
    _, b = frames(theta)
    bw = model.h * b * omega[:, None]
    return _prefix_excl(bw) + 0.5 * bw


def centripetal_accelerations(model: RodModel, theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Velocity-dependent part of the centre accelerations, ``-h sum_j w_ij a_j omega_j^2``."""
    a, _ = frames(theta)
    aw = -model.h * a * (omega**2)[:, None]
    return _prefix_excl(aw) + 0.5 * aw


def generalized_from_centre_forces(model: RodModel, theta: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Generalised forces of centre forces ``f`` (N, 2): ``Q_j = h b_j . (f_j/2 + sum_{i>j} f_i)``."""
    _, b = frames(theta)
    tail = _suffix_excl(f) + 0.5 * f
    return model.h * np.sum(b * tail, axis=1)


def generalized_from_node_forces(model: RodModel, theta: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Generalised forces of node forces ``f`` (N+1, 2): ``Q_j = h b_j . sum_{k>j} f_k``
    (the force on the clamped node 0 does no work)."""
    _, b = frames(theta)
    tail = np.cumsum(f[:0:-1], axis=0)[::-1]  # sum_{k >= j+1} f_k for j = 0..N-1
    return model.h * np.sum(b * tail, axis=1)


@lru_cache(maxsize=8)
def lower_weights(n: int) -> np.ndarray:
    """``w_ij`` (N, N): 1 for ``j < i``, 1/2 on the diagonal, 0 above (read-only, cached)."""
    w = np.tril(np.ones((n, n)), -1)
    w[np.diag_indices(n)] = 0.5
    w.setflags(write=False)
    return w


def weight_matrix(model: RodModel) -> np.ndarray:
    """``W_jk = sum_i m_i w_ij w_ik`` (constant, N x N): the mass matrix is
    ``h^2 W * cos(theta_j - theta_k) + diag(J)``."""
    return model.weight_matrix


def mass_matrix(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Mass matrix ``M(theta)`` of the kinetic energy ``1/2 sum m_i |c_i'|^2 + 1/2 sum J_i theta_i'^2``."""
    c, s = np.cos(theta), np.sin(theta)
    m = (model.h**2) * weight_matrix(model) * (np.outer(c, c) + np.outer(s, s))
    m[np.diag_indices_from(m)] += model.rot_inertia
    return m


@lru_cache(maxsize=8)
def _strictly_lower(n: int) -> np.ndarray:
    out = np.tri(n, k=-1, dtype=bool)
    out.setflags(write=False)
    return out


def _apply(t: np.ndarray, v: np.ndarray, transpose: bool = False) -> np.ndarray:
    """2x2 tensors with entries ``xx, xy, yx, yy`` (4, N) (or their transposes) applied to vectors ``v`` (N, 2)."""
    xy, yx = (t[2], t[1]) if transpose else (t[1], t[2])
    return np.stack([t[0] * v[:, 0] + xy * v[:, 1], yx * v[:, 0] + t[3] * v[:, 1]], axis=1)


def gram_form(entries: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """``F_jk = sum_i w_ij w_ik left_j^T D_i right_k`` (N, N) in O(N^2) for per-centre 2x2
    tensors ``D_i`` with entries ``xx, xy, yx, yy`` (4, N) (:func:`outer_entries`) and
    per-element vectors ``left``, ``right`` (N, 2).

    With ``left = right = b`` (the directions of the centre Jacobian) it is ``G^T D G``: the
    generalised matrix of centre forces ``df_i = -D_i dc_i``; with ``right = a`` it maps the
    angles through the centre velocities (``dv_i/dtheta_k = -h w_ik a_k omega_k``). Since
    ``sum_i w_ij w_ik D_i = S_m + D_m/2`` with ``m = max(j, k)`` and ``S_m = sum_{i>m} D_i`` off the
    diagonal (``S_j + D_j/4`` on it), each triangle is a rank-2 product.
    """
    n = entries.shape[-1]
    tail = np.zeros_like(entries)
    np.cumsum(entries[:, :0:-1], axis=1, out=tail[:, -2::-1])
    t_off = tail + 0.5 * entries
    lower = _apply(t_off, left, transpose=True) @ right.T  # [j, k] = left_j^T T_j right_k, used for j > k
    upper = left @ _apply(t_off, right).T  # [j, k] = left_j^T T_k right_k, used for j < k
    out = np.where(_strictly_lower(n), lower, upper)
    idx = np.arange(n)
    out[idx, idx] = np.sum(left * _apply(tail + 0.25 * entries, right), axis=1)
    return out


def outer_entries(g: np.ndarray, e: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Entries ``xx, xy, yx, yy`` (4, N) of the per-centre tensors ``g_i e_i f_i^T`` for weights
    ``g`` (N,) and vectors ``e``, ``f`` (N, 2)."""
    return np.stack([g * e[:, 0] * f[:, 0], g * e[:, 0] * f[:, 1], g * e[:, 1] * f[:, 0], g * e[:, 1] * f[:, 1]])
