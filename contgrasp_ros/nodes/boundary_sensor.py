"""boundary_sensor: rod state + object boundary -> contact state (rho, alpha, delta, s_o, contact set).

A thin wrapper of :func:`contgrasp_core.contact.sense` (paper eqs. (4), (5), Definition 1) of the
rod state's arm shape, in the object's start-pose frame when the object moves
(:attr:`~contgrasp_ros.plumbing.convert.RodArrays.sensed_shape`). Every rod state is answered on
``/contgrasp/contact`` (a state sent twice with the same answer:
:class:`~contgrasp_ros.nodes.lockstep.Answered`), the sampled ones again on
``/contgrasp/contact/sampled``; the arm's own ``theta`` and ``kappa`` go along for the holding
law. Bad input is dropped and counted (:mod:`contgrasp_ros.plumbing.faults`). docs/ros.md, "Nodes".
"""

from __future__ import annotations

from collections import deque
from typing import Any

from rclpy.node import Node

from contgrasp_core.contact import load_sensing, sense
from contgrasp_core.errors import ContgraspError
from contgrasp_core.scenario import PAPER
from contgrasp_msgs.msg import ContactState, RodState
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.cdr import Codec, MessageView
from contgrasp_ros.plumbing.convert import RodArrays, contact_fields, require_finite, rod_state_arrays
from contgrasp_ros.nodes.lockstep import Answered
from contgrasp_ros.plumbing.diagnostics import Diagnostics
from contgrasp_ros.plumbing.faults import DropCounter, guarded
from contgrasp_ros.plumbing.parameters import declare
from contgrasp_ros.plumbing.runtime import FinishPolicy, ObjectTracker, run_node, sim_time_by_default
from contgrasp_ros.plumbing.stamps import StampGate


RECENT = 16  # contact states kept for the sampled stream's announcements that arrive late


class BoundarySensor(Node):
    """Senses the contact kinematics of every rod state against the current object."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__("boundary_sensor", **node_kwargs)
        sim_time_by_default(self)
        declare(self, "contact_tolerance", PAPER.sensing.contact_tolerance, "contact where delta >= -tolerance [m]", lo=0.0, hi=1.0)
        self.drops = DropCounter(self)
        self.stamps = StampGate(self)
        self.diagnostics = Diagnostics(self, self.drops)
        self.finish = FinishPolicy(self, watch_simulator=True)
        # The latched object and the first rod state race (e.g. on one executor): a state that
        # arrives first is kept and sensed as soon as the object is there, so the lock-step
        # simulator is not left waiting for its first couple.
        # (a decoded or typed message, its arrays, the message as it came)
        self.waiting: tuple[MessageView | RodState, RodArrays, bytes | RodState] | None = None
        self.object = ObjectTracker(self, self.drops, self.stamps, on_change=self._sense_waiting)
        self.sensed = 0
        self.answered = Answered()  # (the rod state sensed last and its contact state)
        # the contact states last published (the sampled announcement of a state can arrive after
        # the next states: the executor takes the per-step topic first) and a sampled step
        # announced before its state was sensed
        self.recent: deque[tuple[int, bytes]] = deque(maxlen=RECENT)  # (step, serialized contact state)
        self.sampled_step: int | None = None
        # the loop's messages go in and out serialized (contgrasp_ros.plumbing.cdr: no conversion to
        # Python message objects); a typed message passed to the callbacks directly works too
        self.rod_codec, self.contact_codec = Codec(RodState), Codec(ContactState)
        load_sensing()  # (the compiled sensing, now rather than at the run's first state)
        self.pub = self.create_publisher(ContactState, topics.CONTACT, qos.STREAM)
        self.pub_sampled = self.create_publisher(ContactState, topics.CONTACT_SAMPLED, qos.STREAM)
        self.create_subscription(RodState, topics.ROD_STATE, self.on_rod_state, qos.STREAM, raw=True)
        self.create_subscription(RodState, topics.ROD_STATE_SAMPLED, self.on_sampled, qos.STREAM, raw=True)

    @guarded(topics.ROD_STATE)
    def on_rod_state(self, data: bytes | RodState) -> None:
        """Validate a rod state (serialized, or a message) and sense it (or keep it until the
        object is known)."""
        if self.answered.again(data):  # (a state sent again: the controller may not have had its answer)
            self.pub.publish(self.answered.answer)
            return
        try:
            msg = self.rod_codec.message(data)
            rod = rod_state_arrays(msg)
            self.stamps.admit(topics.ROD_STATE, msg.header, rod.step)
        except ContgraspError as exc:
            self.drops.drop_error(topics.ROD_STATE, exc)
            return
        if self.object.boundary is None:
            if self.waiting is not None and self.waiting[2] != data:  # (not the same state sent again)
                self.drops.drop(topics.ROD_STATE, "no object yet", "a newer rod state arrived before the object")
            self.waiting = (msg, rod, data)
            return
        self._sense(msg, rod, data)

    def _sense(self, msg: Any, rod: RodArrays, data: bytes | RodState) -> None:
        boundary = self.object.boundary
        assert boundary is not None  # (sensed only once the object is known)
        try:
            state = sense(rod.sensed_shape, boundary, rod.radius, tol=float(self.get_parameter("contact_tolerance").value))
            require_finite("the sensed contact state", state.rho, state.alpha, state.delta, state.s_o, state.foot)
        except ContgraspError as exc:
            self.drops.drop_error(topics.ROD_STATE, exc)
            return
        shape = (rod.theta, rod.kappa) if rod.kappa.size else None  # (a rod state may leave kappa out)
        out = self.contact_codec.encode(contact_fields(state, msg.header, rod.step, shape))
        self.pub.publish(out)
        self.answered.keep(data, out)
        self.sensed += 1
        self.recent.append((rod.step, out))
        if self.sampled_step is not None and rod.step >= self.sampled_step:
            if rod.step == self.sampled_step:
                self.pub_sampled.publish(out)
            self.sampled_step = None  # (a later step: the sampled one was lost on the way)

    @guarded(topics.ROD_STATE_SAMPLED)
    def on_sampled(self, data: bytes | RodState) -> None:
        """A sampled rod state: publish its contact state on the sampled stream, now if it was
        sensed already, else once it is (only the step is read: the state itself is sensed from
        the per-step stream)."""
        try:
            msg = self.rod_codec.message(data)
            step = int(msg.step)
            self.stamps.admit(topics.ROD_STATE_SAMPLED, msg.header, step)
        except ContgraspError as exc:
            self.drops.drop_error(topics.ROD_STATE_SAMPLED, exc)
            return
        sensed = next((out for k, out in reversed(self.recent) if k == step), None)
        if sensed is not None:
            self.pub_sampled.publish(sensed)
        elif not self.recent or step > self.recent[-1][0] or step == 0:  # (step 0: a new run)
            self.sampled_step = step
        # (else an older state this node never sensed: dropped or lost on the way, nothing to republish)

    def _sense_waiting(self) -> None:
        """A new object: sense the state kept until it came; a state taken again is sensed anew."""
        self.answered.reset()
        waiting, self.waiting = self.waiting, None
        if waiting is not None:
            self._sense(*waiting)


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros boundary_sensor``."""
    return run_node(BoundarySensor, args)


if __name__ == "__main__":
    raise SystemExit(main())
