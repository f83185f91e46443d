"""What the quality node computes from a message, shared with offline analysis.

:func:`contact_quality` is the quality node's step (Sec. IV: W and Q1..Q3). The boundary
sensor's step is :func:`contgrasp_core.contact.sense` of the rod state's
:attr:`~contgrasp_ros.plumbing.convert.RodArrays.shape` (paper eqs. (4) and (5),
Definition 1). ``contgrasp analyze`` calls the same two functions on recorded messages, so a
recomputation from a recording reproduces the topics exactly. No ROS imports: both run on
messages decoded without ROS as well.
"""

from __future__ import annotations

from contgrasp_core.boundary import Boundary
from contgrasp_core.quality import GraspQuality, grasp_quality
from contgrasp_ros.plumbing.convert import ContactArrays

__all__ = ["contact_quality"]


def contact_quality(c: ContactArrays, boundary: Boundary, tol: float, ref: tuple[float, float]) -> GraspQuality:
    """Gramian W and Q1..Q3 of a sensed contact state; ``tol < 0`` uses the sensor's tolerance."""
    phi = boundary.tangent_angle(c.s_o)
    return grasp_quality(c.s, c.shadow, phi, c.delta, tol=c.tol if tol < 0 else tol, ref=ref)
