"""Grasp maps, the continuum grasp Gramian and grasp quality metrics (paper Sec. IV).

Point grasp maps and the discrete grasp map (Definition 2); the continuum grasp map (eq. (14))
over the contact set (Definition 1) and its Gramian ``W = int_S G G^T ds`` (Prop. 4.1), in arm
arclength; ``Q1 = lambda_min(W)``, ``Q2 = det W``, ``Q3 = lambda_min / lambda_max`` and their
discrete analogues. Trapezoidal quadrature whose cells are cut where the contact set ends
(second order); :func:`continuum_operator` makes Prop. 4.1 concrete. docs/quality.md, "Grasp
maps and metrics".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import float_array, instance
from .boundary import Boundary
from .contact import ContactState
from .errors import InvalidParameterError

_MAX_LEVER = 1e50  # |gamma - ref| beyond this overflows the Gramian's squared moments
_MAX_ENTRY = 1e100  # grasp-map / Gramian entries beyond this overflow the metrics

__all__ = [
    "point_grasp_maps",
    "discrete_grasp_map",
    "singular_value_metrics",
    "contact_weights",
    "gramian",
    "weighted_gramian",
    "continuum_operator",
    "GraspQuality",
    "metrics_from_gramian",
    "grasp_quality",
    "quality_of_state",
]


def _points_angles(gamma: ArrayLike, phi: ArrayLike, ref: ArrayLike) -> tuple[NDArray, NDArray]:
    g = float_array("contact points", gamma)
    p = float_array("tangent angles", phi)
    r = float_array("reference point", ref)
    if g.ndim != 2 or g.shape[1] != 2 or p.shape != (len(g),):
        raise InvalidParameterError(
            f"contact points must be (n, 2) and tangent angles (n,), got {g.shape} and {p.shape}"
        )
    if r.shape != (2,) or not np.all(np.isfinite(r)):
        raise InvalidParameterError(f"reference point must be two finite numbers, got {ref!r}")
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(p))):
        raise InvalidParameterError("contact points and tangent angles must be finite")
    if np.any(np.abs(g - r) > _MAX_LEVER):
        raise InvalidParameterError(f"contact points must lie within {_MAX_LEVER:.0e} of the reference point")
    return g - r, p


def point_grasp_maps(gamma: ArrayLike, phi: ArrayLike, ref: ArrayLike = (0.0, 0.0)) -> NDArray[np.float64]:
    """Point grasp maps ``G_i = [I2; (gamma_i^perp)^T] R(phi_i)``, shape (n, 3, 2).

    Column 1 maps a unit force along the boundary tangent t(phi_i), column 2 along the inward
    normal, to the wrench (f_x, f_y, torque about ``ref``).
    """
    g, p = _points_angles(gamma, phi, ref)
    c, s = np.cos(p), np.sin(p)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (n, 2, 2)
    perp = np.stack([-g[:, 1], g[:, 0]], -1)  # R(pi/2) gamma
    upper = np.broadcast_to(np.eye(2), (len(g), 2, 2))
    stacked = np.concatenate([upper, perp[:, None, :]], axis=1)  # (n, 3, 2)
    return stacked @ rot


def discrete_grasp_map(gamma: ArrayLike, phi: ArrayLike, ref: ArrayLike = (0.0, 0.0)) -> NDArray[np.float64]:
    """Discrete grasp map ``G~ = [G_1 G_2 ... G_n]`` (Definition 2), shape (3, 2n)."""
    maps = point_grasp_maps(gamma, phi, ref)
    return np.concatenate(list(maps), axis=1) if len(maps) else np.zeros((3, 0))


class SingularValueMetrics(TypedDict):
    """What :func:`singular_value_metrics` returns (a plain dict)."""

    sigma_min: float
    volume: float
    isotropy: float
    singular_values: list[float]


def singular_value_metrics(grasp_map: ArrayLike) -> SingularValueMetrics:
    """Classical metrics of a grasp map of any shape (m, k): its min(m, k) singular values.

    ``sigma_min``, ``volume = prod sigma_i`` and ``isotropy = sigma_min / sigma_max`` (0 for a
    zero map). A map with fewer columns than rows has ``sigma_min = 0`` (it cannot span the
    wrench space).
    """
    g = float_array("grasp map", grasp_map)
    if g.ndim != 2 or not np.all(np.isfinite(g)):
        raise InvalidParameterError(f"grasp map must be a finite 2-D matrix, got shape {g.shape}")
    if np.any(np.abs(g) > _MAX_ENTRY):
        raise InvalidParameterError(f"grasp map entries must be within +-{_MAX_ENTRY:.0e}")
    m, k = g.shape
    try:
        sv = np.linalg.svd(g, compute_uv=False) if g.size else np.zeros(0)
    except np.linalg.LinAlgError as exc:
        raise InvalidParameterError(f"the grasp map's singular values cannot be computed: {exc}") from exc
    sv = np.concatenate([sv, np.zeros(max(0, m - len(sv)))])  # rank-deficient by shape
    smax = float(sv.max()) if len(sv) else 0.0
    with np.errstate(over="ignore", under="ignore"):
        volume = float(np.prod(sv))
    if not np.isfinite(volume):
        raise InvalidParameterError("the grasp map's volume (product of singular values) overflows; rescale it")
    return {
        "sigma_min": float(sv.min()) if len(sv) else 0.0,
        "volume": volume,
        "isotropy": float(sv.min() / smax) if smax > 0 else 0.0,
        "singular_values": [float(v) for v in sv],
    }


def contact_weights(s: ArrayLike, delta: ArrayLike, tol: float | ArrayLike = 0.0) -> NDArray[np.float64]:
    """Quadrature weights of ``int_S f ds`` on the arm grid, S = {delta >= -tol}.

    Trapezoidal on cells fully in contact; a cell whose end points disagree is cut at the
    linear zero crossing of ``delta + tol`` and its in-contact part integrated by the
    trapezoidal rule with the integrand linearly interpolated to the cut.
    """
    ss = float_array("s", s)
    if ss.ndim != 1 or len(ss) < 2 or not np.all(np.abs(ss) <= _MAX_ENTRY) or np.any(np.diff(ss) <= 0):
        raise InvalidParameterError(f"s must be a finite, strictly increasing grid of >= 2 points within +-{_MAX_ENTRY:.0e}")
    d = float_array("delta", delta)
    if d.shape != ss.shape or not np.all(np.abs(d) <= _MAX_ENTRY):
        raise InvalidParameterError(f"delta must be finite (within +-{_MAX_ENTRY:.0e}) with the grid's shape {ss.shape}, got {d.shape}")
    t = float_array("contact tolerance", tol)
    if t.shape not in ((), ss.shape) or not np.all(np.abs(t) <= _MAX_ENTRY) or np.any(t < 0):
        raise InvalidParameterError("contact tolerance must be finite and >= 0 (a scalar or one value per grid node)")
    c = d + t
    h = np.diff(ss)
    c0, c1 = c[:-1], c[1:]
    in0, in1 = c0 >= 0, c1 >= 0
    w = np.zeros_like(ss)
    full = in0 & in1
    w[:-1] += np.where(full, 0.5 * h, 0.0)
    w[1:] += np.where(full, 0.5 * h, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        # fraction of the cell, measured from the in-contact end, up to the crossing
        frac0 = np.where(in0 & ~in1, c0 / (c0 - c1), 0.0)
        frac1 = np.where(in1 & ~in0, c1 / (c1 - c0), 0.0)
    # in-contact part [s_i, s_i + t h]: f(s_i)(2 - t) t h / 2 + f(s_{i+1}) t^2 h / 2
    w[:-1] += 0.5 * h * (frac0 * (2 - frac0) + frac1**2)
    w[1:] += 0.5 * h * (frac0**2 + frac1 * (2 - frac1))
    return w


def _weights_and_maps(
    s: ArrayLike, gamma: ArrayLike, phi: ArrayLike, delta: ArrayLike, tol: float | ArrayLike, ref: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    return contact_weights(s, delta, tol), point_grasp_maps(gamma, phi, ref)


def gramian(
    s: ArrayLike,
    gamma: ArrayLike,
    phi: ArrayLike,
    delta: ArrayLike,
    *,
    tol: float | ArrayLike = 0.0,
    ref: ArrayLike = (0.0, 0.0),
) -> tuple[NDArray[np.float64], float]:
    """Gramian ``W = int_S G(s) G(s)^T ds`` (Prop. 4.1) and the contact length ``int_S ds``.

    ``gamma``/``phi`` are the contact (shadow) points and boundary tangent angles along the
    arm grid ``s``; ``delta`` the contact depth (eq. (5)).
    """
    w = contact_weights(s, delta, tol)
    return weighted_gramian(gamma, phi, w, ref), float(w.sum())


def weighted_gramian(gamma: ArrayLike, phi: ArrayLike, weights: ArrayLike, ref: ArrayLike = (0.0, 0.0)) -> NDArray[np.float64]:
    """``W = sum_i w_i G_i G_i^T`` with the point grasp maps ``G_i`` (Definition 2) and any
    weights: the arclength quadrature of :func:`contact_weights` gives the Gramian of Prop. 4.1
    (:func:`gramian`); contact forces give the force-weighted variant of docs/holding.md."""
    maps = point_grasp_maps(gamma, phi, ref)
    w = float_array("weights", weights)
    if w.shape != (len(maps),) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InvalidParameterError(f"weights must be {len(maps)} finite numbers >= 0, got shape {w.shape}")
    return np.einsum("i,iak,ibk->ab", w, maps, maps)


def continuum_operator(
    s: ArrayLike,
    gamma: ArrayLike,
    phi: ArrayLike,
    delta: ArrayLike,
    *,
    tol: float | ArrayLike = 0.0,
    ref: ArrayLike = (0.0, 0.0),
) -> NDArray[np.float64]:
    """Discretised continuum grasp map ``[sqrt(w_1) G_1 ... sqrt(w_n) G_n]`` (eq. (14)).

    Its singular values equal ``sqrt(eig(W))`` of :func:`gramian` (Prop. 4.1).
    """
    w, maps = _weights_and_maps(s, gamma, phi, delta, tol, ref)
    return np.concatenate(list(maps * np.sqrt(w)[:, None, None]), axis=1)


@dataclass(frozen=True)
class GraspQuality:
    """Continuum grasp quality: W, its eigenvalues (ascending), Q1..Q3, contact length."""

    W: NDArray[np.float64]
    eigenvalues: NDArray[np.float64]
    Q1: float
    Q2: float
    Q3: float
    contact_length: float

    @property
    def has_contact(self) -> bool:
        """False when the contact set is empty (then W = 0 and Q1 = Q2 = Q3 = 0)."""
        return self.contact_length > 0.0


def metrics_from_gramian(W: ArrayLike, contact_length: float = np.nan) -> GraspQuality:
    """Q1 = lambda_min(W), Q2 = det W = prod lambda_i, Q3 = lambda_min / lambda_max (0 if W = 0)."""
    w = float_array("W", W)
    if w.ndim != 2 or w.shape[0] != w.shape[1] or w.shape[0] == 0 or not np.all(np.isfinite(w)):
        raise InvalidParameterError(f"W must be a finite, non-empty square matrix, got shape {w.shape}")
    if np.any(np.abs(w) > _MAX_ENTRY):
        raise InvalidParameterError(f"W must have entries within +-{_MAX_ENTRY:.0e}")
    try:
        length = float(contact_length) if np.ndim(contact_length) == 0 else None
    except (TypeError, ValueError):
        length = None
    if length is None or not (np.isnan(length) or 0.0 <= length < np.inf):  # NaN: unknown
        raise InvalidParameterError(f"contact_length must be a number >= 0 (or NaN), got {contact_length!r}")
    try:
        lam = np.linalg.eigvalsh(0.5 * (w + w.T))
    except np.linalg.LinAlgError as exc:
        raise InvalidParameterError(f"the eigenvalues of W cannot be computed: {exc}") from exc
    lam = np.clip(lam, 0.0, None)  # W is positive semi-definite; clip rounding below zero
    q3 = float(lam[0] / lam[-1]) if lam[-1] > 0 else 0.0
    with np.errstate(over="ignore", under="ignore"):
        q2 = float(np.prod(lam))
    if not np.isfinite(q2):
        raise InvalidParameterError("det W overflows; rescale W")
    return GraspQuality(W=w, eigenvalues=lam, Q1=float(lam[0]), Q2=q2, Q3=q3, contact_length=length)


def grasp_quality(
    s: ArrayLike,
    gamma: ArrayLike,
    phi: ArrayLike,
    delta: ArrayLike,
    *,
    tol: float | ArrayLike = 0.0,
    ref: ArrayLike = (0.0, 0.0),
) -> GraspQuality:
    """Q1..Q3 of a grasp configuration given as arrays along the arm (e.g. from a recording)."""
    W, length = gramian(s, gamma, phi, delta, tol=tol, ref=ref)
    return metrics_from_gramian(W, length)


def quality_of_state(
    state: ContactState,
    boundary: Boundary,
    *,
    tol: float | ArrayLike | None = None,
    ref: ArrayLike = (0.0, 0.0),
) -> GraspQuality:
    """Q1..Q3 of a sensed contact state (optimal grasp, simulated rod, recorded shape).

    ``tol`` defaults to the tolerance the state was sensed with.
    """
    instance("state", state, ContactState)
    instance("boundary", boundary, Boundary)
    phi = boundary.tangent_angle(state.s_o)
    return grasp_quality(state.s, state.foot, phi, state.delta, tol=state.tol if tol is None else tol, ref=ref)
