"""Which grasps hold, before simulating: the wrench capacity of a continuum contact (beyond the
paper; docs/holding.md, "A measure that predicts holding", eqs. (M1)-(M4)).

Q1-Q3 (Sec. IV) measure how well the contact set spans the wrench space, not what it can resist.
The arm presses the object along its contact set (Definition 1) with a bounded line pressure and
Coulomb friction; the wrenches it can exert form a convex set ``K`` (M1) with support function
``h`` (M2), and ``Q_H = min_{|d| = 1} h(d)`` (M3) is the largest wrench resisted in every
direction (per unit pressure bound: metres). :func:`static_capacity` rates the paper's optimal
grasp of Sec. III, :func:`cage_capacity` the contact set the holding law will press (M4).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import float_array, real
from ..control.hold_law import HOLDING_LAWS
from ..errors import ContgraspError, InvalidParameterError
from ..quality import contact_weights

if TYPE_CHECKING:
    from ..arm import BasePose
    from ..boundary import Boundary
    from ..quality_map import MapSpec
    from ..scenario import Scenario

__all__ = ["WrenchCapacity", "wrench_generators", "support", "wrench_capacity", "static_capacity", "static_capacity_column",
           "cage_capacity", "cage_wrap", "check_reach", "SEARCH_DIRECTIONS"]

Array = NDArray[np.float64]

SEARCH_DIRECTIONS = 2000
"""Directions of the first search for (M3)'s minimum (a Fibonacci sphere), each of the best
refined by Nelder-Mead."""


@dataclass(frozen=True)
class WrenchCapacity:
    """(M3): ``measure`` Q_H (m: N of wrench per N/m of pressure bound), the weakest
    ``direction`` (unit, in ``(f_x, f_y, tau / a)``) and the ``contact_length`` (m) integrated."""

    measure: float
    direction: Array
    contact_length: float


def wrench_generators(gamma: ArrayLike, phi: ArrayLike, mu: float, ref: ArrayLike = (0.0, 0.0),
                      scale: float = 1.0) -> Array:
    """The two edge wrenches ``g+-`` of (M2) at each contact point ``gamma`` (n, 2) of a
    counter-clockwise boundary with tangent angle ``phi`` (n,): shape (n, 2, 3)."""
    g = float_array("contact points", gamma)
    p = float_array("tangent angles", phi)
    if g.ndim != 2 or g.shape[1] != 2 or p.shape != (len(g),) or not (np.isfinite(g).all() and np.isfinite(p).all()):
        raise InvalidParameterError(f"contact points must be (n, 2) and tangent angles (n,), finite; got {g.shape}, {p.shape}")
    mu = real("friction coefficient mu", mu, lo=0.0)
    a = real("torque scale", scale, lo=0.0, lo_open=True)
    c = float_array("reference point", ref)
    if c.shape != (2,) or not np.isfinite(c).all():
        raise InvalidParameterError(f"reference point must be two finite numbers, got {ref!r}")
    t = np.stack([np.cos(p), np.sin(p)], axis=-1)
    n = np.stack([-t[:, 1], t[:, 0]], axis=-1)  # (the object lies to the left of a counter-clockwise tangent)
    lever = g - c
    out = np.empty((len(g), 2, 3))
    for k, sign in enumerate((1.0, -1.0)):
        f = n + sign * mu * t
        out[:, k, :2] = f
        out[:, k, 2] = (lever[:, 0] * f[:, 1] - lever[:, 1] * f[:, 0]) / a
    return out


def support(generators: Array, weights: Array, directions: ArrayLike) -> Array:
    """(M2) per unit pressure bound for each row of ``directions`` (k, 3): ``sum_i w_i max(0,
    d . g+_i, d . g-_i)``."""
    d = np.atleast_2d(np.asarray(directions, dtype=float))
    proj = np.einsum("ijc,kc->kij", generators, d)  # (k, n, 2)
    return np.asarray(np.maximum(proj.max(axis=2), 0.0) @ weights, dtype=float)


def _sphere(count: int) -> Array:
    """``count`` nearly uniform unit vectors (Fibonacci sphere)."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    r = np.sqrt(1.0 - z * z)
    ang = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([r * np.cos(ang), r * np.sin(ang), z], axis=-1)


def wrench_capacity(s: ArrayLike, gamma: ArrayLike, phi: ArrayLike, delta: ArrayLike, *, mu: float,
                    tol: float | ArrayLike = 0.0, ref: ArrayLike = (0.0, 0.0), scale: float = 1.0) -> WrenchCapacity:
    """Q_H (M3) of a grasp given along the arm grid ``s`` as Q1-Q3 take it
    (:func:`contgrasp_core.quality.grasp_quality`): contact points ``gamma``, boundary tangent
    angles ``phi``, contact depth ``delta``, tolerance ``tol``; Coulomb ``mu``; torques about
    ``ref`` scaled by ``scale`` (m; the object's nominal radius). The minimum over the sphere:
    the best of :data:`SEARCH_DIRECTIONS` directions, the five best refined by Nelder-Mead."""
    from scipy.optimize import minimize

    w = contact_weights(s, delta, tol)
    gen = wrench_generators(gamma, phi, mu, ref, scale)
    if len(gen) != len(w):
        raise InvalidParameterError(f"contact points ({len(gen)}) and the arm grid ({len(w)}) differ in length")
    length = float(w.sum())
    if length == 0.0:
        return WrenchCapacity(0.0, np.array([1.0, 0.0, 0.0]), 0.0)
    on = w > 0
    gen, w = gen[on], w[on]
    dirs = _sphere(SEARCH_DIRECTIONS)
    h = support(gen, w, dirs)

    def on_sphere(x: Array) -> float:
        norm = float(np.linalg.norm(x))
        return float(support(gen, w, x / norm)[0]) if norm > 0 else np.inf

    best_value, best_dir = float(h.min()), dirs[int(np.argmin(h))]
    for k in np.argsort(h)[:5]:
        res = minimize(on_sphere, dirs[k], method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14 * length,
                                                                           "maxiter": 4000})
        if res.fun < best_value:
            best_value, best_dir = float(res.fun), res.x / np.linalg.norm(res.x)
    return WrenchCapacity(max(best_value, 0.0), np.asarray(best_dir, dtype=float), length)


def static_capacity(spec: MapSpec, base: BasePose, mu: float) -> WrenchCapacity:
    """Q_H (M3) of the optimal grasp of Sec. III from ``base`` (the quality map's problem and
    contact set, paper units: :func:`contgrasp_core.quality_map.optimal_grasp` from its cold
    starts), with Coulomb ``mu``, torques about the object's reference (an outline's centroid) scaled by its
    nominal radius: the measure before any simulation. :class:`ContgraspError` when the grasp
    cannot be solved from ``base``."""
    return _static(spec, spec.boundary(), base, mu, None)[0]


def static_capacity_column(spec: MapSpec, bases: list[BasePose], mu: float) -> list[WrenchCapacity | None]:
    """Q_H (M3) along one polar angle's valid map bases in increasing distance, each grasp
    warm-started from the previous one as the quality map's column walk does
    (:func:`contgrasp_core.quality_map.quality_map`): the very grasps whose Q1-Q3 the map reports
    (a cold start may solve another local optimum, or none). ``None`` where a grasp cannot be
    solved."""
    boundary = spec.boundary()
    warm: Any = None
    out: list[WrenchCapacity | None] = []
    for base in bases:
        try:
            cap, warm = _static(spec, boundary, base, mu, warm)
        except ContgraspError:
            cap = None
        out.append(cap)
    return out


def _static(spec: MapSpec, boundary: Boundary, base: BasePose, mu: float, warm: Any) -> tuple[WrenchCapacity, Any]:
    """Q_H of the optimal grasp from ``base`` and the grasp (a warm start for the next base)."""
    from ..quality_map import optimal_grasp

    problem, res = optimal_grasp(spec, boundary, base, warm)
    s = problem.s
    cap = wrench_capacity(s, boundary.point(res.s_o), boundary.tangent_angle(res.s_o), problem.arm.radius(s) - res.rho,
                          mu=mu, tol=spec.contact_tol, ref=spec.object.reference, scale=spec.object.radius)
    return cap, res


def cage_capacity(scenario: Scenario, mu: float) -> WrenchCapacity:
    """(M4): Q_H (M3) of the contact set the holding law will press, before simulating: the
    closed loop's static rest under eq. (19) with the cage's gains at the close gap ``g_f``
    (:func:`_cage_rest`), and the enclosing band (H3) on it (nodes with ``rho - r <= g_f + band``,
    cut at the linear crossing as Q1-Q3 cut the contact set) pressed at the shadow points.
    Coulomb ``mu``, torques about the scenario's reference scaled by the object's nominal radius;
    SI (Q_H in m). :class:`ContgraspError` when the rest cannot be solved."""
    law, foot = _cage_rest(scenario, "close_gap")
    s, m = law.settings, scenario.rod
    in_band = s.close_gap + s.band - (foot.signed_distance - m.radius(m.s_nodes))
    return wrench_capacity(m.s_nodes, foot.foot, foot.phi, in_band, mu=mu, ref=scenario.reference,
                           scale=scenario.object.radius)


def cage_wrap(scenario: Scenario) -> float:
    """The wrap angle (H3, rad) of the holding law's cage at rest at its clearance: how much of
    the object the arm surrounds from this base before the law can close (it closes at
    ``wrap_angle``). :class:`ContgraspError` when the rest cannot be solved."""
    from ..control.hold_law import wrap_angle

    law, foot = _cage_rest(scenario, "clearance")
    s, m = law.settings, scenario.rod
    band = foot.signed_distance - m.radius(m.s_nodes) <= s.clearance + s.band
    return wrap_angle(foot.theta, foot.alpha, band)


def check_reach(scenario: Scenario) -> None:
    """Refuse, before simulating, a holding-law scenario whose cage cannot close: its rest at the
    clearance (:func:`cage_wrap`) wraps less of the object than the law's ``wrap_angle``, so the
    close never starts (the arm hovers; a free object is never held). The planned hold's planner
    is the holding law: its scenarios are checked too. The paper's law passes."""
    if scenario.law not in HOLDING_LAWS:
        return
    wrap, need = cage_wrap(scenario), scenario.hold_law.wrap_angle
    if wrap < need:
        raise InvalidParameterError(
            f"the holding law cannot close on {scenario.object.text()} from this base: its cage at rest wraps "
            f"{wrap:.2f} rad of the object and the close starts at wrap_angle {need:.2f} rad (a longer arm, a base "
            "nearer the object or a smaller wrap_angle)")


class CageRest(NamedTuple):
    """The cage at rest at the nodes: shadow points ``foot``, boundary tangent angles ``phi``,
    signed distances of the centreline ``signed_distance`` (m), node angles ``theta`` and contact
    angles ``alpha`` (eq. (4))."""

    foot: Array
    phi: Array
    signed_distance: Array
    theta: Array
    alpha: Array


def _cage_rest(scenario: Scenario, gap: str) -> tuple[Any, CageRest]:
    """The holding law and its cage's rest: the closed loop's static rest under eq. (19) with the
    cage's gains at the law's ``gap`` setting (``clearance`` or ``close_gap``)
    (:func:`~contgrasp_core.control.rod_feedback.rest_shape`)."""
    from ..contact import sense
    from ..control.hold_law import HoldController, cage_gains
    from ..control.rod_feedback import rest_shape
    from ..rod import Obstacle, chain

    # (the planned hold's cage is its planner's: the holding law, without computing the plan)
    law, m = (replace(scenario, law="reactive") if scenario.law == "hold" else scenario).controller(), scenario.rod
    if not isinstance(law, HoldController):
        raise InvalidParameterError(f"the cage is the holding law's; the scenario's law is {scenario.law!r}")
    s = law.settings
    obstacle = Obstacle(scenario.object.boundary())
    theta = rest_shape(m, obstacle, cage_gains(m, law.object_radius, s, getattr(s, gap), law.length_unit))
    foot = obstacle.project(chain.nodes(m, theta))
    shape = chain.arm_shape(m, theta)
    contact = sense(shape, scenario.object.boundary(), m.radius(m.s_nodes))
    return law, CageRest(foot.foot, foot.phi, foot.signed_distance, shape.theta, contact.alpha)
