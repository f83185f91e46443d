"""Planar Cosserat/Kirchhoff rod dynamics (paper eqs. (17), (18): dynamics, boundary conditions).

Reduced coordinates (element angles; exactly inextensible and unshearable), implicit
time stepping with Newton, drag, damping, couple control and penalty contact with any
:class:`~contgrasp_core.boundary.Boundary`; a closed-loop runner for the feedback law of
:mod:`contgrasp_core.control`.
See ``docs/rod.md``.
"""

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
