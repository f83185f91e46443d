"""boundary_sensor: rod state + object boundary -> contact state (rho, alpha, delta, s_o, contact set).

Thin wrapper of :func:`contgrasp_ros.evaluate.sense_rod_state` (:func:`contgrasp_core.contact.sense`,
paper eqs. rho_alpha_definition, delta, Definition 1). Malformed rod states or objects are dropped with a throttled warning and counted.
"""

from __future__ import annotations

from rclpy.node import Node

from contgrasp_core.errors import ContgraspError
from contgrasp_msgs.msg import ContactState, RodState
from contgrasp_ros import qos
from contgrasp_ros.convert import contact_to_msg, rod_state_arrays
from contgrasp_ros.evaluate import sense_rod_state
from contgrasp_ros.runtime import DropCounter, ObjectTracker, declare, run_node


class BoundarySensor(Node):
    """Senses the contact kinematics of every rod state against the current object."""

    def __init__(self, **node_kwargs: object) -> None:
        super().__init__("boundary_sensor", **node_kwargs)  # type: ignore[arg-type]
        declare(self, "contact_tolerance", 0.0, "contact where delta >= -tolerance [m]", lo=0.0, hi=1.0)
        self.drops = DropCounter(self)
        # The latched object and the first rod state race (e.g. on one executor): a state that
        # arrives first is kept and sensed as soon as the object is there, so the lock-step
        # simulator is not left waiting for its first couple.
        self.waiting: RodState | None = None
        self.object = ObjectTracker(self, self.drops, on_change=self._sense_waiting)
        self.sensed = 0
        self.pub = self.create_publisher(ContactState, qos.TOPIC_CONTACT, qos.STREAM)
        self.create_subscription(RodState, qos.TOPIC_ROD_STATE, self.on_rod_state, qos.STREAM)

    def on_rod_state(self, msg: RodState) -> None:
        boundary = self.object.boundary
        if boundary is None:
            self.waiting = msg
            return
        try:
            tol = self.get_parameter("contact_tolerance").value
            state = sense_rod_state(rod_state_arrays(msg), boundary, tol)
        except ContgraspError as exc:
            self.drops.drop(qos.TOPIC_ROD_STATE, str(exc))
            return
        self.pub.publish(contact_to_msg(state, msg.header, msg.step))
        self.sensed += 1

    def _sense_waiting(self) -> None:
        msg, self.waiting = self.waiting, None
        if msg is not None:
            self.on_rod_state(msg)


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros boundary_sensor``."""
    return run_node(BoundarySensor, args)


if __name__ == "__main__":
    raise SystemExit(main())
