"""grasp_quality: contact state -> continuum grasp quality (W, Q1..Q3) at a configurable rate.

Thin wrapper of :func:`contgrasp_ros.plumbing.evaluate.contact_quality` (paper Sec. IV, Prop. 4.1) over
the run's one contact set: the contact states' own tolerance (the sensor's, the scenario's
``SensingSettings.contact_tolerance``); the node has no tolerance of its own. It reads the
sensor's sampled stream, ``/contgrasp/contact/sampled`` (every ``sample_period`` of the
simulator, 0.01 s by default): more evaluations than that need the per-step stream, remapped
(``--ros-args -r /contgrasp/contact/sampled:=/contgrasp/contact``).
Malformed contact states or objects, bad stamps and states that arrive before the object are
dropped and counted (``/diagnostics``).
"""

from __future__ import annotations

import math
from typing import Any

from rclpy.node import Node

from contgrasp_core.errors import ContgraspError
from contgrasp_core.scenario import PAPER
from contgrasp_msgs.msg import ContactState, GraspQuality
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.convert import ContactArrays, contact_arrays, quality_to_msg, require_finite
from contgrasp_ros.plumbing.evaluate import contact_quality
from contgrasp_ros.plumbing.diagnostics import Diagnostics
from contgrasp_ros.plumbing.faults import DropCounter, guarded
from contgrasp_ros.plumbing.parameters import declare
from contgrasp_ros.plumbing.runtime import FinishPolicy, ObjectTracker, run_node, sim_time_by_default
from contgrasp_ros.plumbing.stamps import StampGate


class GraspQualityNode(Node):
    """Evaluates Q1..Q3 of the sensed contact set: the first state in each ``1 / rate_hz`` slot of
    simulated time (slots from t = 0, so the evaluated steps do not drift when states are lost)."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__("grasp_quality", **node_kwargs)
        sim_time_by_default(self)
        paper = PAPER.node_parameters("grasp_quality")
        declare(self, "rate_hz", paper["rate_hz"], "evaluations per simulated second (0 = every contact state)", lo=0.0, hi=1e6)
        declare(self, "reference_x", paper["reference_x"], "wrench reference point x [m] (object frame origin)", lo=-1e6, hi=1e6)
        declare(self, "reference_y", paper["reference_y"], "wrench reference point y [m]", lo=-1e6, hi=1e6)
        self.drops = DropCounter(self)
        self.stamps = StampGate(self)
        self.diagnostics = Diagnostics(self, self.drops)
        self.finish = FinishPolicy(self, watch_simulator=True)
        # the latched object and the first contact states race (as in the sensor): the newest
        # state that arrived first is kept and evaluated as soon as the object is there
        self.waiting: tuple[ContactState, ContactArrays] | None = None
        # (the boundary's tables on arrival: the first evaluation is not ~0.3 s late)
        self.object = ObjectTracker(self, self.drops, self.stamps, on_change=self._evaluate_waiting, prepare=True)
        self.last_slot: int | None = None  # the 1/rate_hz slot of simulated time last evaluated
        self.pub = self.create_publisher(GraspQuality, topics.QUALITY, qos.STREAM)
        self.create_subscription(ContactState, topics.CONTACT_SAMPLED, self.on_contact, qos.STREAM)

    @guarded(topics.CONTACT_SAMPLED)
    def on_contact(self, msg: ContactState) -> None:
        """Validate a contact state; evaluate and publish its quality when the rate allows."""
        try:
            c = contact_arrays(msg)
            self.stamps.admit(topics.CONTACT_SAMPLED, msg.header, c.step)
        except ContgraspError as exc:
            self.drops.drop_error(topics.CONTACT_SAMPLED, exc)
            return
        if self.object.boundary is None:
            if self.waiting is not None:
                self.drops.drop(topics.CONTACT_SAMPLED, "no object yet", "a newer contact state arrived before the object")
            self.waiting = (msg, c)
            return
        self._evaluate(msg, c)

    def _evaluate_waiting(self) -> None:
        waiting, self.waiting = self.waiting, None
        if waiting is not None:
            self._evaluate(*waiting)

    def _evaluate(self, msg: ContactState, c: ContactArrays) -> None:
        boundary = self.object.boundary
        assert boundary is not None  # (evaluated only once the object is known)
        rate = self.get_parameter("rate_hz").value
        if rate > 0:  # the first state of each 1/rate slot of simulated time (a new run starts again)
            slot = math.floor(c.t * rate + 1e-9)
            if slot == self.last_slot:
                return
            self.last_slot = slot
        ref = (self.get_parameter("reference_x").value, self.get_parameter("reference_y").value)
        try:
            q = contact_quality(c, boundary, -1.0, ref)  # the sensor's contact set: one per run
            require_finite("the grasp quality", q.W, q.Q1, q.Q2, q.Q3, q.contact_length)
        except ContgraspError as exc:
            self.drops.drop_error(topics.CONTACT_SAMPLED, exc)
            return
        self.pub.publish(quality_to_msg(q, msg.header, msg.step, c.tol))


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros grasp_quality``."""
    return run_node(GraspQualityNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
