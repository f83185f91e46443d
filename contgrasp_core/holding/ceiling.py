"""The muscles' ceiling of a grasp (beyond the paper; docs/holding.md, "The muscles' ceiling", (M5)).

With the arm at rest in a shape, which load could *any* activation within the muscles' bound
(:attr:`~contgrasp_core.rod.RodModel.muscle_bound`) hold? Statics of the discrete rod (paper
eq. (17) at rest, free tip eq. (18)): the total couple at joint ``k`` balances the moments of the
contact forces beyond it, ``EI_k kappa_k + u_k = M_k(f)``; the forces lie in Coulomb's cone at
the elements touching the object; the object is in balance under them and the load ``c d``. The
largest ``c`` with ``|u_k| <= u_max,k`` is a linear programme, one per load direction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InvalidParameterError
from .measure import wrench_generators

if TYPE_CHECKING:
    from ..boundary import Boundary
    from ..rod import RodModel

__all__ = ["MuscleCeiling", "muscle_ceiling"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MuscleCeiling:
    """(M5) per load direction: ``capacity`` (N, scaled wrench space; ``inf`` along a direction
    the contact resists with unbounded muscles), ``holds_shape`` whether any activation within
    the bound holds the shape at all (else every capacity is 0), ``contacts`` the elements
    taken as touching, ``binding`` the joint whose muscle limits each direction most (the
    largest dual of its bound; -1 where no bound limits it)."""

    capacity: Array
    holds_shape: bool
    contacts: int
    binding: NDArray[np.intp]


def joint_moments(rod: RodModel, theta: Array, forces: Array) -> Array:
    """The moments ``M_k`` (N,) about each joint of centre forces ``forces`` (N, 2) on the
    elements beyond it (half of the joint's own element): the total couple a joint must carry
    at rest, the sum from ``k`` to the tip of the generalised forces (eqs. (17), (18))."""
    from ..rod import chain

    q = chain.generalized_from_centre_forces(rod, theta, forces)
    return np.asarray(np.cumsum(q[::-1])[::-1], dtype=float)


def moment_columns(rod: RodModel, theta: Array, elements: NDArray[np.intp], forces: Array) -> Array:
    """The joint moments (N, n) of each unit force ``forces[j]`` (n, 2) on the arm at the centre
    of element ``elements[j]`` alone (:func:`joint_moments`, column by column)."""
    cols = np.empty((rod.n_elements, len(elements)))
    for j, (element, force) in enumerate(zip(elements, forces, strict=True)):
        f = np.zeros((rod.n_elements, 2))
        f[element] = force
        cols[:, j] = joint_moments(rod, theta, f)
    return cols


def muscle_ceiling(rod: RodModel, boundary: Boundary, theta: ArrayLike, *, mu: float, directions: ArrayLike,
                   ref: tuple[float, float], scale: float, tol: float) -> MuscleCeiling:
    """(M5) of the rod at rest in the element angles ``theta`` on ``boundary``: the elements whose
    surface is within ``tol`` (m) of the object touch it (at their feet on the boundary); Coulomb
    ``mu``; ``directions`` (k, 3) in the scaled wrench space (torque about ``ref`` over ``scale``,
    as :func:`~contgrasp_core.holding.experiment.wrench_directions`)."""
    from scipy.optimize import linprog

    from ..rod import chain

    th = np.asarray(theta, dtype=float)
    dirs = np.atleast_2d(np.asarray(directions, dtype=float))
    if th.shape != (rod.n_elements,) or not np.all(np.isfinite(th)):
        raise InvalidParameterError(f"theta must be the rod's {rod.n_elements} finite element angles, got shape {th.shape}")
    if dirs.shape[1] != 3 or not np.all(np.isfinite(dirs)):
        raise InvalidParameterError(f"load directions must be finite rows (fx, fy, torque), got shape {dirs.shape}")
    if not (np.isfinite(tol) and tol >= 0):
        raise InvalidParameterError(f"contact tolerance must be a finite number >= 0, got {tol!r}")
    proj = boundary.project(chain.centres(rod, th))
    touching = np.flatnonzero(proj.signed_distance - rod.r_centres <= tol)
    gen = wrench_generators(proj.foot[touching], proj.phi[touching], mu, ref, scale).reshape(-1, 3)  # (2n, 3): on the object
    cols = moment_columns(rod, th, touching[np.arange(len(gen)) // 2], -gen[:, :2])  # (the object pushes back on the arm)
    elastic = rod.joint_ei * rod.joint_curvature(th)
    bound = rod.muscle_bound
    n = len(gen)
    a_ub, b_ub = None, None  # (the muscles' bound, the same for every direction; none when unbounded)
    if bound is not None:
        moments = np.hstack([cols, np.zeros((len(cols), 1))])
        a_ub, b_ub = np.vstack([moments, -moments]), np.concatenate([bound + elastic, bound - elastic])
    out = np.empty(len(dirs))
    binding = np.full(len(dirs), -1)
    for i, d in enumerate(dirs):  # unknowns: the cone's edge weights (n) and the load c; the arm balances -c d
        a_eq = np.hstack([gen.T, d[:, None]])
        res = linprog(np.r_[np.zeros(n), -1.0], A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=np.zeros(3), bounds=(0, None),
                      method="highs")
        if res.status == 2:  # infeasible even unloaded: the muscles cannot hold this shape
            return MuscleCeiling(np.zeros(len(dirs)), False, len(touching), np.full(len(dirs), -1))
        if res.status == 3:
            out[i] = np.inf
        elif res.status == 0 and res.x is not None:
            out[i] = max(0.0, float(res.x[-1]))
            if bound is not None:  # (the duals of joint k's two rows, upper and lower)
                dual = np.abs(res.ineqlin.marginals[: len(bound)]) + np.abs(res.ineqlin.marginals[len(bound):])
                binding[i] = int(np.argmax(dual)) if dual.max() > 0 else -1
        else:
            raise InvalidParameterError(f"the muscles' ceiling along {d.tolist()} did not solve: {res.message}")
    return MuscleCeiling(out, True, len(touching), binding)
