"""RViz / Foxglove markers of the scene: the arm as a thick line strip, the object outline (where
the object is, when it moves) and the nodes in contact."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from contgrasp_core.boundary import Boundary
from contgrasp_core.rod.body import to_object_frame, to_world
from contgrasp_core.rod.session import Observation

__all__ = ["scene_markers"]


def _points(xy: np.ndarray) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=0.0) for x, y in xy]


@lru_cache(maxsize=4)
def _outline(boundary: Boundary) -> np.ndarray:
    """The closed outline in the object's frame (257 samples): once per boundary."""
    _, pts = boundary.sample(256)
    return np.vstack([pts, pts[:1]])


@lru_cache(maxsize=4)
def _fixed_outline_points(boundary: Boundary) -> list[Point]:
    """The outline's points where a fixed object stays (shared by every marker array: read only)."""
    return _points(_outline(boundary))


def scene_markers(boundary: Boundary, obs: Observation, header: Header, centroid: tuple[float, float] | None = None,
                  contact_tol: float = 1e-4) -> MarkerArray:
    """Markers for one rod observation (contact = rod surface within ``contact_tol`` of the object).
    A movable object (``obs.body``, with its ``centroid`` at the start pose) is drawn where it is."""
    arm = Marker(header=header, ns="arm", id=0, type=Marker.LINE_STRIP, action=Marker.ADD)
    arm.scale.x = float(2.0 * np.mean(obs.radius))
    arm.color = ColorRGBA(r=0.55, g=0.35, b=0.75, a=0.8)
    arm.points = _points(obs.x)
    arm.pose.orientation.w = 1.0
    arm_in_object = obs.x
    outline = Marker(header=header, ns="object", id=1, type=Marker.LINE_STRIP, action=Marker.ADD)
    if obs.body is not None and centroid is not None:
        c = np.asarray(centroid, dtype=float)
        outline.points = _points(to_world(_outline(boundary), obs.body.q, c))
        arm_in_object = to_object_frame(obs.x, obs.body.q, c)
    else:
        outline.points = _fixed_outline_points(boundary)
    outline.scale.x = float(0.005 * boundary.length)
    outline.color = ColorRGBA(r=0.2, g=0.2, b=0.2, a=1.0)
    outline.pose.orientation.w = 1.0
    gap = boundary.project(arm_in_object).signed_distance - obs.radius
    contact = Marker(header=header, ns="contact", id=2, type=Marker.POINTS, action=Marker.ADD)
    contact.scale.x = contact.scale.y = float(np.mean(obs.radius))
    contact.color = ColorRGBA(r=1.0, g=0.5, b=0.0, a=1.0)
    contact.points = _points(obs.x[gap <= contact_tol])
    contact.pose.orientation.w = 1.0
    return MarkerArray(markers=[arm, outline, contact])
