"""A node's status on ``/diagnostics`` (:class:`Diagnostics`): its level and message, its own
key/values, the drop counts and its process id (docs/ros.md, "Nodes")."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Header

from contgrasp_ros.plumbing import topics
from contgrasp_ros.plumbing.faults import DropCounter

__all__ = ["Diagnostics", "Status"]

Status = tuple[int, str, dict[str, str]]


class Diagnostics:
    """The node's status on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray, one
    DiagnosticStatus named after the node): every ``period_s`` of wall time (steady-clock timer)
    and at once on the first drop; :meth:`update` publishes a node's events (the simulator's
    states) at most every ``min_period_s`` of wall time and at once when the level or the
    message changes. ``build()`` gives (level, message, key/values); the drop counts
    (:meth:`DropCounter.key_values`) are added. Default: OK / WARN when messages were dropped.
    ``summary()`` gives (level, message) alone, cheaply: :meth:`update` then builds the values
    only when it publishes (the simulator updates after every state)."""

    def __init__(self, node: Node, drops: DropCounter, build: Callable[[], Status] | None = None, period_s: float = 1.0,
                 min_period_s: float = 0.2, summary: Callable[[], tuple[int, str]] | None = None) -> None:
        from contgrasp_ros.plumbing import qos

        self._node = node
        self._drops = drops
        self._build = build
        self._summary = summary
        self._min_period = min_period_s
        self._last: tuple[float, int, str] | None = None  # (wall time, level, message) of the last publication
        self.pub = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, qos.STREAM)
        drops.on_first_drop = self.publish
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        node.create_timer(period_s, drops.guard("diagnostics timer", self.publish), clock=self._steady)

    def _values(self) -> Status:
        if self._build is not None:
            level, message, values = self._build()
        else:
            total = self._drops.total
            level = DiagnosticStatus.WARN if total else DiagnosticStatus.OK
            message, values = (f"{total} messages dropped" if total else "ok"), {}
        return self._with_drops(level), message, values

    def _with_drops(self, level: int) -> int:
        return DiagnosticStatus.WARN if self._drops.total and level == DiagnosticStatus.OK else level

    def status(self, values: Status | None = None) -> DiagnosticStatus:
        """The current DiagnosticStatus (of ``values`` when given: a :meth:`_values` result)."""
        level, message, kv = values if values is not None else self._values()
        # (the pid: a launcher tells its own nodes from another graph's of the same names)
        kv = {**kv, **self._drops.key_values(), "pid": str(os.getpid())}
        return DiagnosticStatus(level=level, name=topics.status_name(self._node.get_name(), self._node.get_namespace()), message=message, hardware_id="contgrasp",
                                values=[KeyValue(key=k, value=v) for k, v in kv.items()])

    def publish(self, stamp: Time | None = None, values: Status | None = None) -> None:
        """Publish the status now (stamped with ``stamp`` or the node clock)."""
        values = values if values is not None else self._values()
        header_stamp = stamp if stamp is not None else self._node.get_clock().now().to_msg()
        self.pub.publish(DiagnosticArray(header=Header(stamp=header_stamp), status=[self.status(values)]))
        self._last = (time.monotonic(), values[0], values[1])

    def update(self, stamp: Time | None = None) -> None:
        """Publish the status if its level or message changed since the last publication or
        ``min_period_s`` wall seconds passed since then (a status per event, a few per second
        at most: building and delivering one after every simulator state cost more than the
        state itself, benchmarks/RESULTS.md, ros_loop)."""
        last = self._last
        if last is not None and time.monotonic() - last[0] < self._min_period:
            if self._summary is not None:
                level, message = self._summary()
                if (self._with_drops(level), message) == last[1:]:
                    return
            elif self._values()[:2] == last[1:]:
                return
        self.publish(stamp)
