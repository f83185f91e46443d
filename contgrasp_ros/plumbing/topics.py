"""The graph's topic names: the one list, imported by the nodes, the launcher, the recorder and
offline analysis (no rclpy import, so ``contgrasp analyze`` reads recordings without ROS).
The quality-of-service profiles are in :mod:`contgrasp_ros.plumbing.qos`."""

from __future__ import annotations

__all__ = ["OBJECT", "ROD_STATE", "CONTACT", "COUPLE", "ROD_STATE_SAMPLED", "CONTACT_SAMPLED", "QUALITY", "MARKERS", "DIAGNOSTICS", "CLOCK", "OBJECT_POSE",
           "OBJECT_TWIST", "OBJECT_WRENCH", "APPLY_WRENCH"]

OBJECT = "/contgrasp/object"
"""contgrasp_msgs/ObjectBoundary, transient-local: the object's sampled boundary."""
ROD_STATE = "/contgrasp/rod_state"
"""contgrasp_msgs/RodState: the rod at the nodes, one per control step."""
CONTACT = "/contgrasp/contact"
"""contgrasp_msgs/ContactState: sensed (rho, alpha, delta, s_o) and the contact set."""
COUPLE = "/contgrasp/couple"
"""contgrasp_msgs/CoupleControl: the feedback couple at the joints, answering one rod state."""
ROD_STATE_SAMPLED = "/contgrasp/rod_state/sampled"
"""contgrasp_msgs/RodState: the rod state every ``sample_period`` of simulated time (the
simulator's parameter), the first and the final state always. For observers (the quality node,
the launcher's monitor, Foxglove): every reader of a per-step topic costs the loop a wake-up
each step (docs/ros.md, "How fast"), so only the loop and the recorder read those."""
CONTACT_SAMPLED = "/contgrasp/contact/sampled"
"""contgrasp_msgs/ContactState: the sensor's contact state of each sampled rod state (the same
steps as :data:`ROD_STATE_SAMPLED`)."""
QUALITY = "/contgrasp/quality"
"""contgrasp_msgs/GraspQuality: the Gramian W and Q1..Q3."""
OBJECT_POSE = "/contgrasp/object_pose"
"""geometry_msgs/PoseStamped (frame ``world``), a movable object only, one per rod state: its
centroid and its rotation from the start pose (the object's frame is parallel to ``world`` at
the start)."""
OBJECT_TWIST = "/contgrasp/object_twist"
"""geometry_msgs/TwistStamped (frame ``world``), a movable object only, one per rod state: the
centroid's velocity and the rotation rate."""
OBJECT_WRENCH = "/contgrasp/object_wrench"
"""geometry_msgs/WrenchStamped (frame ``world``), subscribed by the simulator: a wrench held on
the movable object from the next control period on (force at the centroid, torque about it),
added to the scripted disturbance, until the next message (zeros release it)."""
APPLY_WRENCH = "/rod_simulator/apply_wrench"
"""contgrasp_msgs/srv/ApplyWrench, the simulator's service (``~/apply_wrench``): a step, ramp or
pulse on the movable object from the next control period on."""
MARKERS = "/contgrasp/markers"
"""visualization_msgs/MarkerArray: the rod and the object for RViz (fixed frame ``world``)."""
DIAGNOSTICS = "/diagnostics"
"""diagnostic_msgs/DiagnosticArray: each node's status."""
CLOCK = "/clock"
"""rosgraph_msgs/Clock: simulated time, published by the simulator."""
