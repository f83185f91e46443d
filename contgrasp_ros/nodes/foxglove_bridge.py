"""foxglove_bridge: the running graph, live in the Foxglove app, without a ROS install.

Serves the run over the Foxglove WebSocket protocol (``foxglove-sdk``; default
``ws://127.0.0.1:8765``): a scene (arm, object, contact nodes) and the rod state, contact,
quality and simulator status as JSON channels, each message logged at its simulated time. By
hand (``ros2 run contgrasp_ros foxglove_bridge``) or inside ``contgrasp-launch --foxglove
[PORT]``; it only listens, the loop does not wait for it. Channels: docs/ros.md, "Watching".
"""

from __future__ import annotations

from typing import Any

import foxglove
import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import Color, LinePrimitive, LinePrimitiveLineType, Point3, SceneEntity, SceneUpdate, Timestamp
from rclpy.node import Node

from contgrasp_core.errors import ContgraspError
from contgrasp_core.rod.body import to_world
from contgrasp_msgs.msg import ContactState, GraspQuality, RodState
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.convert import ContactArrays, RodArrays, contact_arrays, rod_state_arrays
from contgrasp_ros.plumbing.diagnostics import Diagnostics
from contgrasp_ros.plumbing.faults import DropCounter, guarded
from contgrasp_ros.plumbing.parameters import declare
from contgrasp_ros.plumbing.runtime import ObjectTracker, run_node, sim_time_by_default
from contgrasp_ros.plumbing.stamps import StampGate

__all__ = ["FoxgloveBridge", "SCENE", "STATUS"]

SCENE = "contgrasp/scene"
STATUS = "contgrasp/status"
"""(Foxglove channels, named like the graph's topics: under the bridge's namespace.)"""
_ARM = Color(r=0.85, g=0.33, b=0.10, a=1.0)
_OBJECT = Color(r=0.2, g=0.2, b=0.2, a=1.0)
_CONTACT = Color(r=0.0, g=0.45, b=0.74, a=1.0)


def _ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _line(points: np.ndarray, color: Color, thickness: float, loop: bool = False) -> LinePrimitive:
    kind = LinePrimitiveLineType.LineLoop if loop else LinePrimitiveLineType.LineStrip
    return LinePrimitive(type=kind, thickness=thickness, scale_invariant=False, color=color,
                         points=[Point3(x=float(x), y=float(y), z=0.0) for x, y in points])


class FoxgloveBridge(Node):
    """Republishes the graph's topics to a Foxglove WebSocket server."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__("foxglove_bridge", **node_kwargs)
        sim_time_by_default(self)
        host = declare(self, "host", "127.0.0.1", "address the WebSocket server listens on (loopback by default)",
                       read_only=True)
        port = declare(self, "port", 8765, "WebSocket port (0 = any free port)", lo=0, hi=65535, read_only=True)
        declare(self, "scene_period", 0.02, "simulated seconds between scene updates (0 = every rod state)", lo=0.0, hi=1e6)
        self.drops = DropCounter(self)
        self.stamps = StampGate(self)
        self.diagnostics = Diagnostics(self, self.drops)
        self.outline: np.ndarray | None = None  # the object's outline, sampled once per object
        self.object = ObjectTracker(self, self.drops, self.stamps, on_change=self._sample_object)
        self.server = foxglove.start_server(name="contgrasp", host=host, port=port)
        self.port = self.server.port
        ns = self.get_namespace()
        self.scene = SceneUpdateChannel(topics.resolve(SCENE, ns))
        self.json = {name: foxglove.Channel(topics.resolve(name, ns), message_encoding="json") for name in
                     (topics.ROD_STATE, topics.CONTACT, topics.QUALITY, STATUS)}
        self.next_scene_t = 0.0
        self.contact: ContactArrays | None = None
        # (the observers' sampled streams: see contgrasp_ros.plumbing.topics)
        self.create_subscription(RodState, topics.ROD_STATE_SAMPLED, self.on_rod_state, qos.STREAM)
        self.create_subscription(ContactState, topics.CONTACT_SAMPLED, self.on_contact, qos.STREAM)
        self.create_subscription(GraspQuality, topics.QUALITY, self.on_quality, qos.STREAM)
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.on_status, qos.STREAM)
        self.get_logger().info(f"Foxglove WebSocket server on ws://{host}:{self.port} (open it in the Foxglove app)")

    def destroy_node(self) -> None:
        self.server.stop()
        super().destroy_node()

    def _sample_object(self) -> None:
        boundary = self.object.boundary
        self.outline = None if boundary is None else boundary.sample(256)[1]

    @guarded(topics.ROD_STATE_SAMPLED)
    def on_rod_state(self, msg: RodState) -> None:
        try:
            rod = rod_state_arrays(msg)
        except ContgraspError as exc:
            self.drops.drop_error(topics.ROD_STATE_SAMPLED, exc)
            return
        t_ns = _ns(msg.header)
        body = {} if rod.object is None else {"object_q": rod.object.q.tolist(), "object_v": rod.object.v.tolist(),
                                              "object_wrench": rod.object.wrench.tolist()}
        self.json[topics.ROD_STATE].log({
            "step": rod.step, "t": t_ns * 1e-9, "s": rod.s.tolist(), "x": rod.x.tolist(), "y": rod.y.tolist(),
            "theta": rod.theta.tolist(), "kinetic_energy": float(msg.kinetic_energy), **body}, log_time=t_ns)
        period = float(self.get_parameter("scene_period").value)
        if t_ns * 1e-9 + 1e-12 < self.next_scene_t and period > 0:
            return
        self.next_scene_t = t_ns * 1e-9 + period
        self.scene.log(self._scene(msg, rod), log_time=t_ns)

    def _scene(self, msg: RodState, rod: RodArrays) -> SceneUpdate:
        stamp = Timestamp(sec=int(msg.header.stamp.sec), nsec=int(msg.header.stamp.nanosec))
        centreline = np.stack([rod.x, rod.y], -1)
        radius = float(np.mean(rod.radius))
        lines = [_line(centreline, _ARM, thickness=radius)]
        if self.outline is not None:
            o = rod.object
            outline = self.outline if o is None else to_world(self.outline, o.q, o.centroid)
            lines.append(_line(outline, _OBJECT, thickness=0.0015, loop=True))
        c = self.contact
        if c is not None and c.step == rod.step and len(c.in_contact) == len(centreline):
            touching = centreline[c.in_contact]
            if len(touching) > 1:
                lines.append(_line(touching, _CONTACT, thickness=2.2 * radius))
        entity = SceneEntity(timestamp=stamp, frame_id="world", id="grasp", lines=lines)
        return SceneUpdate(entities=[entity])

    @guarded(topics.CONTACT_SAMPLED)
    def on_contact(self, msg: ContactState) -> None:
        try:
            c = contact_arrays(msg)
        except ContgraspError as exc:
            self.drops.drop_error(topics.CONTACT_SAMPLED, exc)
            return
        self.contact = c
        t_ns = _ns(msg.header)
        self.json[topics.CONTACT].log({
            "step": c.step, "t": t_ns * 1e-9, "s": c.s.tolist(), "rho": c.rho.tolist(), "alpha": c.alpha.tolist(),
            "delta": c.delta.tolist(), "in_contact": c.in_contact.tolist()}, log_time=t_ns)

    @guarded(topics.QUALITY)
    def on_quality(self, msg: GraspQuality) -> None:
        t_ns = _ns(msg.header)
        self.json[topics.QUALITY].log({
            "step": int(msg.step), "t": t_ns * 1e-9, "Q1": float(msg.q1), "Q2": float(msg.q2), "Q3": float(msg.q3),
            "contact_length": float(msg.contact_length), "valid": bool(msg.valid)}, log_time=t_ns)

    @guarded(topics.DIAGNOSTICS)
    def on_status(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == topics.status_name("rod_simulator", self.get_namespace()):
                self.json[STATUS].log({kv.key: kv.value for kv in st.values}, log_time=_ns(msg.header))


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros foxglove_bridge``."""
    return run_node(FoxgloveBridge, args)


if __name__ == "__main__":
    raise SystemExit(main())
