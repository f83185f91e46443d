"""Shared node plumbing: parameter declaration with ranges, throttled drop counting, main()."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from contgrasp_core.boundary import Boundary
from contgrasp_core.errors import ContgraspError

__all__ = ["declare", "DropCounter", "FatalNodeError", "ObjectTracker", "make_executor", "run_node"]


class FatalNodeError(ContgraspError):
    """Raised from a callback when the node cannot go on (e.g. the recorder's disk is full):
    :func:`run_node` cleans up and exits with code 1 and the message."""


def make_executor(context: object | None = None) -> Executor:
    """The executor named by ``CONTGRASP_EXECUTOR``: ``single`` (default, SingleThreadedExecutor)
    or ``events`` (rclpy.experimental.EventsExecutor, lower latency). The multi-threaded
    executor is deliberately not offered: on 2 cores its tail latency is large (DESIGN.md)."""
    kind = os.environ.get("CONTGRASP_EXECUTOR", "single")
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind != "single":
        raise ValueError(f"CONTGRASP_EXECUTOR must be 'single' or 'events', got {kind!r}")
    return SingleThreadedExecutor(context=context)


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    read_only: bool = False,
) -> Any:
    """Declare a parameter with a descriptor (and a range for numbers); return its value.

    rclpy enforces the range both for the start-up value (params file / overrides: the node
    refuses to start) and for ``ros2 param set`` at run time (the set is refused, the old value
    stays).
    """
    desc = ParameterDescriptor(description=description, read_only=read_only)
    if lo is not None and hi is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        elif isinstance(default, float):
            desc.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return node.declare_parameter(name, default, desc).value


class DropCounter:
    """Counts dropped messages by reason and warns at most once per ``period_s`` seconds (wall)."""

    def __init__(self, node: Node, period_s: float = 2.0) -> None:
        self._node = node
        self._period = period_s
        self.counts: dict[str, int] = {}

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def drop(self, topic: str, reason: str) -> None:
        key = f"{topic}: {reason.split(':')[0]}"
        self.counts[key] = self.counts.get(key, 0) + 1
        self._node.get_logger().warn(
            f"dropped message on {topic} ({self.total} dropped so far): {reason}",
            throttle_duration_sec=self._period,
        )


class ObjectTracker:
    """Keeps the latest valid object boundary from the transient-local object topic; invalid
    boundaries are dropped and counted (the previous one stays in use). ``on_change`` is
    called after a new boundary was accepted."""

    def __init__(self, node: Node, drops: DropCounter, on_change: Callable[[], None] | None = None) -> None:
        from contgrasp_msgs.msg import ObjectBoundary
        from contgrasp_ros import qos

        self.boundary: Boundary | None = None
        self._drops = drops
        self._topic = qos.TOPIC_OBJECT
        self._on_change = on_change
        node.create_subscription(ObjectBoundary, qos.TOPIC_OBJECT, self._on_object, qos.LATCHED)

    def _on_object(self, msg: object) -> None:
        from contgrasp_ros.convert import boundary_from_msg

        try:
            self.boundary = boundary_from_msg(msg)  # type: ignore[arg-type]
        except ContgraspError as exc:
            self._drops.drop(self._topic, str(exc))
            return
        if self._on_change is not None:
            self._on_change()


def run_node(factory: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Init rclpy, build the node, spin until shutdown (SIGINT/SIGTERM), clean up.

    A node that rejects its start-up parameters exits with code 2 and a one-line reason; a
    :class:`FatalNodeError` while spinning ends it with code 1 (after the node's own clean-up).
    """
    rclpy.init(args=list(args) if args is not None else sys.argv)
    node = None
    code = 0
    try:
        try:
            node = factory()
        except (
            rclpy.exceptions.InvalidParameterValueException,
            rclpy.exceptions.ParameterException,
            ContgraspError,
        ) as exc:
            if isinstance(exc, FatalNodeError):
                print(f"{getattr(factory, '__name__', 'node')}: error: {exc}", file=sys.stderr)
                return 1
            print(f"{getattr(factory, '__name__', 'node')}: invalid parameter: {exc}", file=sys.stderr)
            return 2
        executor = make_executor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except FatalNodeError as exc:
        print(f"{getattr(factory, '__name__', 'node')}: error: {exc}", file=sys.stderr)
        code = 1
    finally:
        if node is not None:
            node.destroy_node()
            code = max(code, int(getattr(node, "exit_code", 0)))  # a failure during the node's own clean-up
        if rclpy.ok():
            rclpy.shutdown()
    return code
