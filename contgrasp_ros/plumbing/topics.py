"""The graph's topic names: the one list, imported by the nodes, the launcher, the recorder and
offline analysis (no rclpy import, so ``contgrasp analyze`` reads recordings without ROS).
The quality-of-service profiles are in :mod:`contgrasp_ros.plumbing.qos`.

The graph's names are relative: a node resolves them under its namespace (none: ``/contgrasp/...``;
``-r __ns:=/r1``: ``/r1/contgrasp/...``). ``/diagnostics`` and ``/clock`` are absolute, as ROS's
conventions have them; a namespaced graph remaps ``/clock`` to ``<namespace>/clock`` on every node
(:func:`namespace_arguments`), so two simulators in one domain keep two clocks (docs/ros.md,
"Namespaces")."""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from typing import Any

__all__ = ["resolve", "message_class", "status_name", "namespace_clock", "namespace_arguments", "recorded_namespace", "GLOBAL", "OBJECT", "ROD_STATE", "CONTACT", "COUPLE", "ROD_STATE_SAMPLED", "CONTACT_SAMPLED", "QUALITY", "MARKERS", "DIAGNOSTICS", "CLOCK", "OBJECT_POSE",
           "OBJECT_TWIST", "OBJECT_WRENCH", "APPLY_WRENCH"]

OBJECT = "contgrasp/object"
"""contgrasp_msgs/ObjectBoundary, transient-local: the object's sampled boundary."""
ROD_STATE = "contgrasp/rod_state"
"""contgrasp_msgs/RodState: the rod at the nodes, one per control step."""
CONTACT = "contgrasp/contact"
"""contgrasp_msgs/ContactState: sensed (rho, alpha, delta, s_o) and the contact set."""
COUPLE = "contgrasp/couple"
"""contgrasp_msgs/CoupleControl: the feedback couple at the joints, answering one rod state."""
ROD_STATE_SAMPLED = "contgrasp/rod_state/sampled"
"""contgrasp_msgs/RodState: the rod state every ``sample_period`` of simulated time (the
simulator's parameter), the first and the final state always. For observers (the quality node,
the launcher's monitor, Foxglove): every reader of a per-step topic costs the loop a wake-up
each step (docs/ros.md, "How fast"), so only the loop and the recorder read those."""
CONTACT_SAMPLED = "contgrasp/contact/sampled"
"""contgrasp_msgs/ContactState: the sensor's contact state of each sampled rod state (the same
steps as :data:`ROD_STATE_SAMPLED`)."""
QUALITY = "contgrasp/quality"
"""contgrasp_msgs/GraspQuality: the Gramian W and Q1..Q3."""
OBJECT_POSE = "contgrasp/object_pose"
"""geometry_msgs/PoseStamped (frame ``world``), a movable object only, one per rod state: its
centroid and its rotation from the start pose (the object's frame is parallel to ``world`` at
the start)."""
OBJECT_TWIST = "contgrasp/object_twist"
"""geometry_msgs/TwistStamped (frame ``world``), a movable object only, one per rod state: the
centroid's velocity and the rotation rate."""
OBJECT_WRENCH = "contgrasp/object_wrench"
"""geometry_msgs/WrenchStamped (frame ``world``), subscribed by the simulator: a wrench held on
the movable object from the next control period on (force at the centroid, torque about it),
added to the scripted disturbance, until the next message (zeros release it)."""
APPLY_WRENCH = "rod_simulator/apply_wrench"
"""contgrasp_msgs/srv/ApplyWrench, the simulator's service (``~/apply_wrench``): a step, ramp or
pulse on the movable object from the next control period on."""
MARKERS = "contgrasp/markers"
"""visualization_msgs/MarkerArray: the rod and the object for RViz (fixed frame ``world``)."""
DIAGNOSTICS = "/diagnostics"
"""diagnostic_msgs/DiagnosticArray: each node's status."""
CLOCK = "/clock"
"""rosgraph_msgs/Clock: simulated time, published by the simulator."""
GLOBAL = (DIAGNOSTICS, "/rosout", "/parameter_events")
"""The topics every graph of a domain shares (each status, log line and parameter event names its node)."""


def _namespace(namespace: str) -> str:
    """``namespace`` absolute and without a trailing slash (the root: ``""``)."""
    return "/" + namespace.strip("/") if namespace.strip("/") else ""


def resolve(name: str, namespace: str = "/") -> str:
    """The absolute name of the graph's ``name`` for a node in ``namespace`` (an absolute name as it is)."""
    return name if name.startswith("/") else f"{_namespace(namespace)}/{name}"


def status_name(node: str, namespace: str = "/") -> str:
    """A node's diagnostic status name: its fully qualified name without the leading slash
    (``rod_simulator``; ``r1/rod_simulator`` under ``/r1``), so statuses of two namespaced graphs on
    the one ``/diagnostics`` stay apart."""
    return resolve(node, namespace).lstrip("/")


def namespace_clock(namespace: str) -> str:
    """The clock of a graph in ``namespace``: ``<namespace>/clock`` (``/clock`` at the root)."""
    return _namespace(namespace) + CLOCK


def namespace_arguments(namespace: str) -> list[str]:
    """The ``--ros-args`` remapping rules that move a node into ``namespace`` with the namespace's
    own clock (``/clock`` is absolute in every node's time source); none for the root namespace."""
    ns = _namespace(namespace)
    return ["-r", f"__ns:={ns}", "-r", f"{CLOCK}:={namespace_clock(ns)}"] if ns else []


def recorded_namespace(names: Iterable[str]) -> str:
    """The namespace a recording was made under, from its topic names: the prefix of its
    :data:`ROD_STATE` (``/`` when none or several graphs' are there, the root's included)."""
    found = {n[: -len(ROD_STATE) - 1] for n in names if n.endswith("/" + ROD_STATE)}
    return next(iter(found)) or "/" if len(found) == 1 else "/"


def message_class(type_name: str) -> Any:
    """The Python class of the ROS message type ``pkg/msg/Name`` (importing ``pkg.msg``, not
    rclpy); ModuleNotFoundError when its package is not installed, AttributeError when the
    package has no such type, ValueError for a name without a package."""
    pkg, _, name = type_name.rpartition("/")
    return getattr(importlib.import_module(pkg.replace("/", ".")), name)
