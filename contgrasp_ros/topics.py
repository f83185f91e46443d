"""The graph's topic names: the one list, imported by the nodes, the launcher, the recorder and
offline analysis (no rclpy import, so ``contgrasp analyze`` reads recordings without ROS).
The quality-of-service profiles are in :mod:`contgrasp_ros.qos`."""

from __future__ import annotations

__all__ = ["OBJECT", "ROD_STATE", "CONTACT", "COUPLE", "QUALITY", "MARKERS", "DIAGNOSTICS", "CLOCK"]

OBJECT = "/contgrasp/object"
"""contgrasp_msgs/ObjectBoundary, transient-local: the object's sampled boundary."""
ROD_STATE = "/contgrasp/rod_state"
"""contgrasp_msgs/RodState: the rod at the nodes, one per control step."""
CONTACT = "/contgrasp/contact"
"""contgrasp_msgs/ContactState: sensed (rho, alpha, delta, s_o) and the contact set."""
COUPLE = "/contgrasp/couple"
"""contgrasp_msgs/CoupleControl: the feedback couple at the joints, answering one rod state."""
QUALITY = "/contgrasp/quality"
"""contgrasp_msgs/GraspQuality: the Gramian W and Q1..Q3."""
MARKERS = "/contgrasp/markers"
"""visualization_msgs/MarkerArray: the rod and the object for RViz (fixed frame ``world``)."""
DIAGNOSTICS = "/diagnostics"
"""diagnostic_msgs/DiagnosticArray: each node's status."""
CLOCK = "/clock"
"""rosgraph_msgs/Clock: simulated time, published by the simulator."""
