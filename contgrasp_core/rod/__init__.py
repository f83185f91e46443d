"""Planar Cosserat/Kirchhoff rod dynamics (paper eqs. (17), (18): dynamics, boundary conditions).

Reduced coordinates (element angles; exactly inextensible and unshearable), implicit
time stepping with Newton, drag, damping, couple control and penalty contact with any
:class:`~contgrasp_core.boundary.Boundary`; a closed-loop runner for the feedback law of
:mod:`contgrasp_core.control`.
See ``docs/rod.md``.

The names below are imported from their modules on first access (module ``__getattr__``): a
process that only needs the rod's geometry (:mod:`contgrasp_core.rod.chain`, as the ROS
boundary sensor and controller) does not import the integrator and the obstacle (scipy.spatial).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from contgrasp_core.rod import chain
    from contgrasp_core.rod.integrator import RodLoads, RodState, RodSystem, StepFailedError, StepOptions
    from contgrasp_core.rod.model import RodModel
    from contgrasp_core.rod.obstacle import Obstacle, ObstacleProjection

__all__ = [
    "RodModel",
    "RodState",
    "RodLoads",
    "RodSystem",
    "StepOptions",
    "StepFailedError",
    "Obstacle",
    "ObstacleProjection",
    "chain",
]

_MODULE_OF = {
    "RodModel": "model",
    "RodState": "integrator",
    "RodLoads": "integrator",
    "RodSystem": "integrator",
    "StepOptions": "integrator",
    "StepFailedError": "integrator",
    "Obstacle": "obstacle",
    "ObstacleProjection": "obstacle",
}


def __getattr__(name: str) -> Any:
    if name not in _MODULE_OF:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_MODULE_OF[name]}"), name)
    globals()[name] = value
    return value
