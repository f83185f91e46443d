"""Reduced-coordinate kinematics of the discrete rod (eq. kinematics, eq. boundary_conditions).

Generalised coordinates are the element angles ``theta`` (N,). With ``a_j = (cos, sin)(theta_j)``
and ``b_j = R(pi/2) a_j``, the nodes are ``x_k = r0 + h sum_{j<k} a_j`` and the element centres
``c_i = r0 + h (sum_{j<i} a_j + a_i / 2)``, so ``r(0) = r0`` and inextensibility/unshearability
hold exactly. The centre Jacobian is ``dc_i/dtheta_j = h w_ij b_j`` with ``w_ij = 1`` for
``j < i``, ``1/2`` for ``j = i``, 0 otherwise. All maps are O(N) cumulative sums except the
mass matrix (O(N^2)).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from contgrasp_core.rod.model import RodModel

__all__ = [
    "frames",
    "nodes",
    "centres",
    "node_angles",
    "centre_velocities",
    "centripetal_accelerations",
    "generalized_from_centre_forces",
    "generalized_from_node_forces",
    "mass_matrix",
    "weight_matrix",
    "weighted_gram",
    "projected_jacobian",
]


def frames(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent ``a`` and normal ``b`` of every element, each (N, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c, s], axis=1), np.stack([-s, c], axis=1)


def nodes(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Node positions ``x_k``, k = 0..N (N+1, 2)."""
    a, _ = frames(theta)
    x = np.empty((len(theta) + 1, 2))
    x[0] = model.base_position
    np.cumsum(model.h * a, axis=0, out=x[1:])
    x[1:] += x[0]
    return x


def centres(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Element centres, the midpoints of consecutive nodes (N, 2)."""
    x = nodes(model, theta)
    return 0.5 * (x[:-1] + x[1:])


def node_angles(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Tangent angle at the nodes: the clamp angle at the base, the mean of adjacent elements
    inside, the last element's angle at the tip (N+1,)."""
    out = np.empty(len(theta) + 1)
    out[0] = model.base_angle
    out[1:-1] = 0.5 * (theta[:-1] + theta[1:])
    out[-1] = theta[-1]
    return out


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
def _lower_weights(n: int) -> np.ndarray:
    w = np.tril(np.ones((n, n)), -1)
    w[np.diag_indices(n)] = 0.5
    return w


def weight_matrix(model: RodModel) -> np.ndarray:
    """``W_jk = sum_i m_i w_ij w_ik`` (constant, N x N): the mass matrix is
    ``h^2 W * cos(theta_j - theta_k) + diag(J)``."""
    return model.weight_matrix


@lru_cache(maxsize=8)
def _max_index(n: int) -> np.ndarray:
    i = np.arange(n)
    return np.maximum.outer(i, i)


def weighted_gram(g: np.ndarray) -> np.ndarray:
    """``sum_i g_i w_ij w_ik`` for per-centre weights ``g`` (N,) in O(N^2): with ``S_m =
    sum_{i>m} g_i`` it is ``S_max(j,k) + g_max/2`` off the diagonal and ``S_j + g_j/4`` on it."""
    n = len(g)
    tail = np.zeros(n)
    np.cumsum(g[:0:-1], out=tail[-2::-1])
    out = (tail + 0.5 * g)[_max_index(n)]
    out[np.diag_indices(n)] = tail + 0.25 * g
    return out


def mass_matrix(model: RodModel, theta: np.ndarray) -> np.ndarray:
    """Mass matrix ``M(theta)`` of the kinetic energy ``1/2 sum m_i |c_i'|^2 + 1/2 sum J_i theta_i'^2``."""
    c, s = np.cos(theta), np.sin(theta)
    m = (model.h**2) * weight_matrix(model) * (np.outer(c, c) + np.outer(s, s))
    m[np.diag_indices_from(m)] += model.rot_inertia
    return m


def projected_jacobian(model: RodModel, theta: np.ndarray, directions: np.ndarray,
                       rows: np.ndarray | None = None) -> np.ndarray:
    """``P_ij = d(dir_i . c_i)/dtheta_j = h w_ij (dir_i . b_j)`` for unit ``directions`` (n, 2)
    at the centres ``rows`` (all by default); shape (n, N)."""
    n = model.n_elements
    w = _lower_weights(n) if rows is None else _lower_weights(n)[rows]
    _, b = frames(theta)
    return model.h * w * (directions @ b.T)
