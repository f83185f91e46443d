"""What the sensing and quality nodes compute from a message, shared with offline analysis.

:func:`sense_rod_state` is the boundary sensor's step (paper eqs. (4) and
(5), Definition 1) and :func:`contact_quality` the quality node's (Sec. IV: W and Q1..Q3).
``contgrasp analyze`` calls the same two functions on recorded messages, so a recomputation
from a recording reproduces the topics exactly. No ROS imports: both run on messages decoded
without ROS as well.
"""

from __future__ import annotations

import numpy as np

from contgrasp_core.arm import ArmShape
from contgrasp_core.boundary import Boundary
from contgrasp_core.contact import ContactState, sense
from contgrasp_core.quality import GraspQuality, grasp_quality
from contgrasp_ros.convert import ContactArrays, RodArrays

__all__ = ["sense_rod_state", "contact_quality"]


def sense_rod_state(rod: RodArrays, boundary: Boundary, tol: float) -> ContactState:
    """Contact kinematics (rho, alpha, delta, s_o, contact set) of a rod state against the object."""
    shape = ArmShape(s=rod.s, r=np.stack([rod.x, rod.y], -1), theta=rod.theta)
    return sense(shape, boundary, rod.radius, tol=tol)


def contact_quality(c: ContactArrays, boundary: Boundary, tol: float, ref: tuple[float, float]) -> GraspQuality:
    """Gramian W and Q1..Q3 of a sensed contact state; ``tol < 0`` uses the sensor's tolerance."""
    phi = boundary.tangent_angle(c.s_o)
    return grasp_quality(c.s, c.shadow, phi, c.delta, tol=c.tol if tol < 0 else tol, ref=ref)
