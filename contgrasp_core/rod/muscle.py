"""Muscles with limits: the active couple of each section saturates at what its muscles can make.

The couple ``u`` of paper eq. (17) is made by longitudinal muscles pulling at a stress of at most
``sigma_max`` (:attr:`RodModel.max_muscle_stress`); the most any fibre layout can make in a
circular section of radius ``r`` is the whole half-section pulling, ``2/3 sigma_max r^3``
(:attr:`RodModel.muscle_bound`, docs/rod.md "Muscles with limits"). Every law's couple passes
through :func:`saturate`, inside the implicit step where the law is state feedback.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.rod.model import RodModel

__all__ = ["saturate", "saturate_jacobian"]

Array = NDArray[np.float64]


def saturate(model: RodModel, u: Array) -> Array:
    """The couple ``u`` (N,) clipped to ``+-model.muscle_bound`` (unchanged when unbounded)."""
    bound = model.muscle_bound
    return u if bound is None else np.clip(u, -bound, bound)


def saturate_jacobian(model: RodModel, u: Array, du: Array) -> Array:
    """``d saturate(u)/dtheta`` for ``du = du/dtheta`` (N, N): the rows of saturated joints vanish."""
    bound = model.muscle_bound
    return du if bound is None else np.where((np.abs(u) < bound)[:, None], du, 0.0)
