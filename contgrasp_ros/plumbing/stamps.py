"""The stamp rule a node applies to the messages it receives (:func:`stamp_problem`,
:class:`StampGate`): invalid stamps, stamps from the future and from the past are dropped, and
a step 0 or a lower step starts a new run (docs/ros.md, "Nodes")."""

from __future__ import annotations

from typing import Any

from rclpy.node import Node

from contgrasp_ros.plumbing.parameters import declare

__all__ = ["stamp_problem", "StampGate"]

_NS = 1_000_000_000


def stamp_problem(sec: int, nanosec: int, step: int | None, newest_ns: int | None, now_ns: int, max_future_s: float,
                  *, check_past: bool = True, newest_step: int | None = None) -> str | None:
    """The stamp rule; returns the drop reason or None.

    * ``invalid stamp``: ``sec < 0`` or ``nanosec >= 1e9``;
    * ``from the future``: more than ``max_future_s`` ahead of the node clock ``now_ns`` - only
      when the clock is valid (``now_ns > 0``; with sim time it is 0 until the first /clock);
    * ``from the past``: older than the newest accepted stamp on the topic (``newest_ns``),
      except for step 0 or a step below the newest accepted step (``newest_step``): the
      simulator was reset or restarted and a new run began - the tracking restarts (its
      first states may have been missed while the restarted publisher was being matched).
    """
    if sec < 0 or not 0 <= nanosec < _NS:
        return "invalid stamp"
    t_ns = sec * _NS + nanosec
    if now_ns > 0 and t_ns - now_ns > max_future_s * _NS:
        return "from the future"
    new_run = step == 0 or (step is not None and newest_step is not None and step < newest_step)
    if check_past and not new_run and newest_ns is not None and t_ns < newest_ns:
        return "from the past"
    return None


class StampGate:
    """Applies :func:`stamp_problem` to the messages a node receives, per topic; declares the
    node's ``max_future_stamp`` parameter (seconds in the node's clock: sim time with
    ``use_sim_time``)."""

    def __init__(self, node: Node) -> None:
        self._node = node
        declare(node, "max_future_stamp", 1.0, "drop messages stamped more than this ahead of the node clock [s]",
                lo=0.0, hi=1e9)
        self.newest_ns: dict[str, int] = {}
        self.newest_step: dict[str, int] = {}

    def admit(self, topic: str, header: Any, step: int | None, *, check_past: bool = True) -> None:
        """Accept the message's stamp (and track it as the newest on ``topic``) or raise
        :class:`~contgrasp_ros.plumbing.convert.MessageError` with the rule's reason. ``check_past=False``
        for topics without an order (the latched object: the newest publication wins)."""
        from contgrasp_ros.plumbing.convert import MessageError

        sec, nanosec = int(header.stamp.sec), int(header.stamp.nanosec)
        now_ns = self._node.get_clock().now().nanoseconds
        max_future = float(self._node.get_parameter("max_future_stamp").value)
        newest = self.newest_ns.get(topic)
        reason = stamp_problem(sec, nanosec, step, newest, now_ns, max_future, check_past=check_past,
                               newest_step=self.newest_step.get(topic))
        if reason is not None:
            raise MessageError(
                f"stamp {sec}.{nanosec:09d} s (step {step}) {reason}: node clock {now_ns / _NS:.9f} s, "
                f"newest accepted {'none' if newest is None else f'{newest / _NS:.9f} s'}",
                reason=reason,
            )
        if check_past:
            self.newest_ns[topic] = sec * _NS + nanosec
            if step is not None:
                self.newest_step[topic] = int(step)

    def reset(self) -> None:
        """Forget the tracked stamps (the node's own reset)."""
        self.newest_ns.clear()
        self.newest_step.clear()
