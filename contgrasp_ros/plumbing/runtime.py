"""Shared node plumbing: parameters with validation, drop counting, the last-resort callback
guard, the stamp rule, the /diagnostics status and main().

Every contgrasp node uses these, so they degrade the same way (docs/ros.md, "Nodes";
docs/RELIABILITY.md): :func:`declare` (a validated parameter: exit 2 at start-up, a refused
``ros2 param set``), :class:`DropCounter` and :func:`guarded` (dropped messages and unexpected
exceptions counted, never raised out of a callback), :class:`StampGate` (the stamp rule),
:class:`Diagnostics` (the node's status), :class:`GuardedSpin`, :func:`sim_time_by_default` and
:class:`FinishPolicy` (``on_finish``).
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from typing import Any, TypeVar, cast

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.signals import uninstall_signal_handlers
from std_msgs.msg import Header

from contgrasp_core.boundary import Boundary
from contgrasp_core.errors import ContgraspError, RunFailure, exit_code, interruption, one_line
from contgrasp_ros.plumbing import topics
from contgrasp_ros.plumbing.executor import LeanExecutor

__all__ = [
    "declare",
    "add_parameter_check",
    "DropCounter",
    "guarded",
    "service_failure",
    "StampGate",
    "stamp_problem",
    "Diagnostics",
    "FatalNodeError",
    "GuardedSpin",
    "ObjectTracker",
    "make_executor",
    "run_node",
    "run_nodes",
    "join_signal_thread",
    "sim_time_by_default",
    "FinishPolicy",
    "ON_FINISH",
    "all_acked",
]

F = TypeVar("F", bound=Callable[..., Any])
Check = Callable[[Any], str | None]
JointCheck = Callable[[dict[str, Any]], str | None]


class FatalNodeError(RunFailure):
    """Raised from a callback when the node cannot go on (e.g. the recorder's disk is full):
    :func:`run_node` cleans up and exits with code 1 and the message. The callback guard lets
    it through."""


def make_executor(context: Context | None = None) -> Executor:
    """The launcher's executor (its monitor, and every node with ``--in-process``), named by
    ``CONTGRASP_EXECUTOR``: ``lean`` (default, :class:`~contgrasp_ros.plumbing.executor.LeanExecutor`),
    ``single`` (rclpy's SingleThreadedExecutor) or ``events`` (rclpy.experimental.EventsExecutor).
    Node processes (:func:`run_node`) always use the lean executor (docs/ros.md). The
    multi-threaded executor is deliberately not offered: on 2 cores its tail latency is large
    (docs/design.md)."""
    kind = os.environ.get("CONTGRASP_EXECUTOR", "lean")
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single":
        return SingleThreadedExecutor(context=context)
    if kind != "lean":
        raise ValueError(f"CONTGRASP_EXECUTOR must be 'lean', 'single' or 'events', got {kind!r}")
    return LeanExecutor(context=context)


# ---------------------------------------------------------------------------- parameters
class _ParameterChecks:
    """The node's one on-set-parameters callback: per-parameter checks (choices) and joint
    checks over all values. rclpy also calls it while a parameter is declared, so a bad
    start-up value raises InvalidParameterValueException (exit code 2 in :func:`run_node`)."""

    ATTR = "_contgrasp_parameter_checks"

    def __init__(self, node: Node) -> None:
        self._node = node
        self.single: dict[str, Check] = {}
        self.joint: list[JointCheck] = []
        node.add_on_set_parameters_callback(self)

    @classmethod
    def of(cls, node: Node) -> _ParameterChecks:
        checks = getattr(node, cls.ATTR, None)
        if checks is None:
            checks = cls(node)
            setattr(node, cls.ATTR, checks)
        return checks

    def __call__(self, params: list[Parameter]) -> SetParametersResult:
        try:
            for p in params:
                check = self.single.get(p.name)
                reason = check(p.value) if check is not None else None
                if reason:
                    return SetParametersResult(successful=False, reason=f"{p.name}: {reason}")
            if self.joint:
                # (rclpy annotates the values as parameter values; they are Parameter objects)
                current = cast("dict[str, Parameter]", self._node.get_parameters_by_prefix(""))
                values = {name: p.value for name, p in current.items()}
                values.update({p.name: p.value for p in params})
                for joint in self.joint:
                    if reason := joint(values):
                        return SetParametersResult(successful=False, reason=reason)
        except Exception as exc:  # a check must never take the parameter service down
            return SetParametersResult(successful=False, reason=f"internal error checking parameters: {type(exc).__name__}: {exc}")
        return SetParametersResult(successful=True)


def _choice_check(choices: Sequence[str]) -> Check:
    return lambda v: None if v in choices else f"must be one of {', '.join(map(repr, choices))}, got {v!r}"


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    read_only: bool = False,
    choices: Sequence[str] | None = None,
) -> Any:
    """Declare a parameter with a descriptor and its validation; return its value.

    The type is fixed by ``default`` (rclpy refuses other types), numbers get the range
    ``[lo, hi]`` (NaN/Inf are out of range) and strings may be restricted to ``choices``
    (checks over several parameters: :func:`add_parameter_check`). rclpy enforces all of it
    both for the start-up value (params file / overrides: the node refuses to start) and for
    ``ros2 param set`` at run time (refused with the reason, the old value stays);
    ``read_only`` parameters cannot be changed at run time at all.
    """
    desc = ParameterDescriptor(description=description, read_only=read_only)
    if lo is not None and hi is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        elif isinstance(default, float):
            desc.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    if choices:
        desc.additional_constraints = f"one of: {', '.join(choices)}"
        _ParameterChecks.of(node).single[name] = _choice_check(choices)
    return node.declare_parameter(name, default, desc).value


def add_parameter_check(node: Node, check: JointCheck) -> None:
    """Add a check over several parameters: ``check(values)`` gets every declared parameter's
    value with the proposed changes applied and returns the reason to refuse them (or None).
    Register it after the parameters it reads are declared."""
    _ParameterChecks.of(node).joint.append(check)


# ---------------------------------------------------------------------------- drops and the guard
class DropCounter:
    """Counts dropped messages per ``<topic>: <reason>`` and warns at most once per
    ``period_s`` wall seconds per key (saying how many were not logged).

    Unexpected exceptions caught by the callback guard are counted the same way under
    ``<where>: internal error: <ExcType>``, logged with their traceback the first time.
    ``on_first_drop`` is called after the first drop (the node's diagnostics publish at once).
    """

    def __init__(self, node: Node, period_s: float = 2.0) -> None:
        self._node = node
        self._period = period_s
        self.counts: dict[str, int] = {}
        self._last_log: dict[str, tuple[float, int]] = {}  # key -> (wall time, count then)
        self.on_first_drop: Callable[[], None] | None = None

    def stopping(self) -> bool:
        """The node's context was shut down (SIGINT/SIGTERM): failures from now on are not faults."""
        return not self._node.context.ok()

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def _absolute(self, where: str) -> str:
        """``where`` as counted and logged: a graph topic (``contgrasp/...``) by its absolute name."""
        return topics.resolve(where, self._node.get_namespace()) if where.startswith("contgrasp/") else where

    def drop(self, topic: str, reason: str, detail: str = "") -> None:
        """Count a dropped message on ``topic`` under the short ``reason``; log ``detail`` (throttled)."""
        topic = self._absolute(topic)
        key = f"{topic}: {reason}"
        self._count(key)
        self._log(key, f"dropped message on {topic}: {detail or reason}")

    def drop_error(self, topic: str, exc: Exception) -> None:
        """Count a drop for a validation/processing error: the reason is the error's ``reason``
        (:class:`~contgrasp_ros.plumbing.convert.MessageError`) or its class name."""
        self.drop(topic, getattr(exc, "reason", None) or type(exc).__name__, str(exc))

    def internal_error(self, where: str, exc: BaseException) -> None:
        """Count an unexpected exception of a callback; log it, with the traceback the first time."""
        where = self._absolute(where)
        key = f"{where}: internal error: {type(exc).__name__}"
        first = key not in self.counts
        self._count(key)
        if first:
            tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
            self._node.get_logger().error(f"internal error in {where} (the node keeps running):\n{tb}")
            self._last_log[key] = (time.monotonic(), self.counts[key])
        else:
            self._log(key, f"internal error in {where}: {type(exc).__name__}: {exc}")

    def guard(self, where: str, fn: F, on_error: Callable[[BaseException, tuple[Any, ...]], Any] | None = None) -> F:
        """``fn`` wrapped so that an unexpected exception is counted (:meth:`internal_error`) and
        ``on_error(exc, args)`` (or None) returned instead; FatalNodeError passes through."""

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            return _call_guarded(self, where, fn, args, kwargs, on_error)

        return cast(F, wrapper)

    def key_values(self) -> dict[str, str]:
        """``dropped_messages`` (total) and one ``dropped: <topic>: <reason>`` entry per key."""
        out = {"dropped_messages": str(self.total)}
        out.update({f"dropped: {key}": str(n) for key, n in sorted(self.counts.items())})
        return out

    def _count(self, key: str) -> None:
        self.counts[key] = self.counts.get(key, 0) + 1
        if self.total == 1 and self.on_first_drop is not None:
            self.on_first_drop()

    def _log(self, key: str, text: str) -> None:
        now, n = time.monotonic(), self.counts[key]
        last_t, last_n = self._last_log.get(key, (-float("inf"), 0))
        if now - last_t < self._period:
            return
        unlogged = n - last_n - 1
        more = f"; {unlogged} more since the last warning" if unlogged > 0 else ""
        self._node.get_logger().warn(f"{text} ({n} dropped for this reason, {self.total} in total{more})")
        self._last_log[key] = (now, n)


def _call_guarded(drops: DropCounter, where: str, fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any],
                  on_error: Callable[[BaseException, tuple[Any, ...]], Any] | None) -> Any:
    try:
        return fn(*args, **kwargs)
    except FatalNodeError:
        raise
    except Exception as exc:
        if (stop := interruption(exc)) is not None:  # (a Ctrl-C inside a compiled kernel: a stop)
            raise stop from None
        if drops.stopping():
            # SIGINT/SIGTERM shut the context down while this callback ran (its publish failed):
            # the node is stopping, not broken
            return None if on_error is None else on_error(exc, args)
        drops.internal_error(where, exc)
        return None if on_error is None else on_error(exc, args)


def guarded(where: str, on_error: Callable[[BaseException, tuple[Any, ...]], Any] | None = None) -> Callable[[F], F]:
    """Method decorator: the last-resort guard of a callback method of an object with a
    ``drops`` :class:`DropCounter` (a node, the object tracker). Direct calls are guarded too."""

    def deco(method: F) -> F:
        @functools.wraps(method)
        def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
            return _call_guarded(self.drops, where, functools.partial(method, self), args, kwargs, on_error)

        return cast(F, wrapper)

    return deco


def service_failure(exc: BaseException, args: tuple[Any, ...]) -> Any:
    """``on_error`` for services with ``success``/``message`` responses (std_srvs): the response
    (the callback's last argument) reports the internal error."""
    resp = args[-1]
    resp.success, resp.message = False, f"internal error: {type(exc).__name__}: {exc}"
    return resp


# ---------------------------------------------------------------------------- stamps
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


# ---------------------------------------------------------------------------- diagnostics
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


# ---------------------------------------------------------------------------- time and the end of a run
def sim_time_by_default(node: Node) -> None:
    """``use_sim_time`` true unless the command line or a parameter file set it: the loop runs in
    the simulator's time (``/clock``), started by hand or by the launcher alike."""
    # rclpy 7.1 keeps the values given on the command line, in --params-file and in the node's
    # parameter_overrides in this mapping; it has no public accessor for "was it given"
    if "use_sim_time" not in node._parameter_overrides:
        node.set_parameters([Parameter("use_sim_time", value=True)])


ON_FINISH = ("idle", "exit", "supervised")


class FinishPolicy:
    """What the node does when the run is over, by its ``on_finish`` parameter: ``idle`` (the
    default) stays up and says so (the simulator can be reset with ``~/reset``; Ctrl-C stops a
    node); ``exit`` ends the process ``grace_s`` wall seconds later, once every subscriber has
    acknowledged what the node published (at most ``finish_ack_timeout`` wall seconds more),
    with status 0 for a finished run and 1 for a failed one; ``supervised`` stays up without a
    word (``contgrasp-launch`` gives it to its nodes: it stops them itself).

    The wait for acknowledgements is what delivers a run's end: a reliable writer repairs a
    subscriber's lost samples only while it exists, so a subscriber starved of CPU for a moment
    (a monitor, a recorder, a test's probe on a loaded machine) lost the final state and status
    for good when the simulator exited a fixed second after finishing.

    The simulator reports the end itself (:meth:`done`); the other nodes learn it from the
    simulator's status on ``/diagnostics`` (``watch_simulator``: state ``finished`` or
    ``failed``; ``running`` again after a reset re-arms the policy). :func:`run_node` ends its
    spin loop when the node's ``stop_requested`` is set and returns ``exit_code``.
    """

    def __init__(self, node: Node, *, watch_simulator: bool, grace_s: float = 1.0) -> None:
        self._node = node
        self._grace = grace_s
        self._ended = False
        declare(node, "on_finish", "idle", "when the run is over: 'idle' (stay up), 'exit' (status 0 finished, 1 failed) or "
                "'supervised' (stay up quietly: a launcher stops the node)",
                choices=ON_FINISH)
        declare(node, "finish_ack_timeout", 10.0, "on_finish exit: wall seconds to wait at most for the subscribers to "
                "acknowledge the node's last messages before it exits", lo=0.0, hi=3600.0)
        node.stop_requested = False  # type: ignore[attr-defined]
        self._simulator = topics.status_name("rod_simulator", node.get_namespace())  # (its status name)
        if watch_simulator:
            from contgrasp_ros.plumbing import qos

            node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_status, qos.STREAM)

    def _on_status(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name != self._simulator:
                continue
            values = {kv.key: kv.value for kv in st.values}
            state = values.get("state")
            if state in ("finished", "failed"):
                try:  # (the simulator's own wording: 4 significant digits, not the status text's 17)
                    detail = f"at t = {float(values['sim_time_s']):.4g} s"
                except (KeyError, ValueError):
                    detail = "(its simulated time unknown)"
                self.done(state == "failed", f"the simulator's run {state} {detail}")
            elif state == "running":
                self._ended = False

    def rearm(self) -> None:
        """A new run started (the simulator's reset)."""
        self._ended = False

    def done(self, failed: bool, what: str, before_exit: Callable[[], None] | None = None) -> None:
        """The run is over (once per run): stay up or schedule the exit, and log which.
        ``before_exit`` runs right before the node stops (the simulator's last status)."""
        if self._ended:
            return
        self._ended = True
        log = self._node.get_logger()
        policy = self._node.get_parameter("on_finish").value
        if policy == "supervised":
            log.debug(f"{what}; staying up until the launcher stops the node (on_finish: supervised)")
            return
        if policy == "idle":
            log.info(f"{what}; staying up (on_finish: idle): call ~/reset on the simulator to run again, "
                     "Ctrl-C to stop, or start the nodes with on_finish:=exit")
            return
        code = 1 if failed else 0
        log.info(f"{what}; exiting with status {code} (on_finish: exit)")
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        timer = None

        def stop() -> None:
            assert timer is not None
            timer.cancel()
            if before_exit is not None:
                before_exit()
            self._wait_for_acknowledgements()
            self._node.exit_code = max(int(getattr(self._node, "exit_code", 0)), code)
            self._node.stop_requested = True

        timer = self._node.create_timer(self._grace, stop, clock=steady)

    def _wait_for_acknowledgements(self) -> None:
        """Block until every reliable publisher's samples are acknowledged by all its matched
        subscribers, ``finish_ack_timeout`` wall seconds at most for them all; a warning names
        the topics still unacknowledged (a subscriber that hung or died unannounced). Ctrl-C
        meanwhile ends the wait."""
        node = self._node
        end = time.monotonic() + node.get_parameter("finish_ack_timeout").value
        pending = []
        for pub in node.publishers:
            if not all_acked(pub, end - time.monotonic(), node.context):
                if not node.context.ok():
                    return
                pending.append(pub.topic_name)
        if pending:
            node.get_logger().warn(f"exiting with messages not acknowledged by every subscriber of {', '.join(pending)} "
                                   "(finish_ack_timeout: a subscriber hung or died)")


def all_acked(publisher: Publisher, seconds: float, context: Context) -> bool:
    """``publisher.wait_for_all_acked`` for at most ``seconds`` (< 0: 0): True once every matched
    reliable subscriber acknowledged its samples; False on the timeout, and when ``context`` was
    shut down meanwhile (Ctrl-C: rclpy's handler shuts it down from another thread, so checking
    the context before the call does not keep the call from failing on it)."""
    try:
        return bool(publisher.wait_for_all_acked(Duration(seconds=max(0.0, seconds))))
    except Exception:
        if context.ok():
            raise
        return False


# ---------------------------------------------------------------------------- the object
class ObjectTracker:
    """Keeps the latest valid object boundary from the transient-local object topic; invalid
    boundaries (malformed, self-intersecting, degenerate, bad stamp) are dropped and counted
    (the previous one stays in use). ``on_change`` is called after a new boundary was accepted.

    The object carries no step: its stamp must be valid and not from the future, but an older
    stamp is accepted (a restarted simulator republishes the object; the newest publication wins).
    ``prepare``: build the boundary's interpolation tables on arrival
    (:meth:`~contgrasp_core.boundary.Boundary.prepare`) rather than at the first state that needs
    them, with the modules they need imported at construction (~0.3 s, at the node's start-up,
    not while a run starts): for a node off the lock-step path (the quality node), not for the
    sensor, whose circle or ellipse never needs them.
    """

    def __init__(self, node: Node, drops: DropCounter, stamps: StampGate,
                 on_change: Callable[[], None] | None = None, prepare: bool = False) -> None:
        from contgrasp_msgs.msg import ObjectBoundary
        from contgrasp_ros.plumbing import qos

        self.boundary: Boundary | None = None
        self.drops = drops
        self._stamps = stamps
        self._topic = topics.OBJECT
        self._on_change = on_change
        self._prepare = prepare
        if prepare:
            Boundary.load_table_modules()
        node.create_subscription(ObjectBoundary, topics.OBJECT, self.on_object, qos.LATCHED)

    @guarded(topics.OBJECT)
    def on_object(self, msg: Any) -> None:
        """Validate and keep the boundary of an ObjectBoundary message."""
        from contgrasp_ros.plumbing.convert import boundary_from_msg

        try:
            boundary = boundary_from_msg(msg)
            self._stamps.admit(self._topic, msg.header, None, check_past=False)
        except ContgraspError as exc:
            self.drops.drop_error(self._topic, exc)
            return
        self.boundary = boundary.prepare() if self._prepare else boundary
        if self._on_change is not None:
            self._on_change()


# ---------------------------------------------------------------------------- main
class GuardedSpin:
    """``executor.spin_once`` that survives a message rclpy cannot take.

    Under load rclpy can fail inside ``take_message`` itself, before any callback (RuntimeError
    "Unable to convert call argument '0' to Python object"; ros2/rclpy#848,
    ros/joint_state_publisher#117): seen once in the soak test, in the launcher, at SIGINT. The
    message is lost to this node (the recorder has its own copy); the failure is counted as an
    internal error of ``executor`` and spinning goes on. If the context has been shut down
    meanwhile it ends as a normal shutdown (:class:`ExternalShutdownException`); more than
    ``max_failures`` failures in a row are re-raised (not a transient failure).
    """

    def __init__(self, executor: Executor, drops: DropCounter, max_failures: int = 1000) -> None:
        self.executor, self.drops, self.max_failures = executor, drops, max_failures
        self.streak = 0

    def __call__(self, timeout_sec: float | None = None) -> None:
        try:
            self.executor.spin_once(timeout_sec=timeout_sec)
        except RuntimeError as exc:
            if isinstance(exc, ContgraspError):  # a RunFailure (FatalNodeError) from a callback ends the node
                raise
            if not self.executor.context.ok():
                raise ExternalShutdownException() from exc
            self.streak += 1
            if self.streak > self.max_failures:
                raise
            self.drops.internal_error("executor", exc)
        else:
            self.streak = 0


def _interrupt_once(signum: int, frame: object) -> None:
    """SIGINT handler of a node process: the first SIGINT stops it (KeyboardInterrupt), and the
    handler ignores every later one before anything else runs, so a burst of Ctrl-C cannot
    land in the clean-up (before, one landed between the first interrupt and
    :func:`_ignore_interrupts`, with a traceback and exit -2)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise KeyboardInterrupt


def _ignore_interrupts() -> None:
    """From here on SIGINT does nothing (the process is already stopping; a node process exits
    right after, and a second Ctrl-C must not cut its clean-up short). Called in-process (tests),
    it leaves SIGINT ignored, which later subprocesses inherit: tests/conftest.py puts it back."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def join_signal_thread() -> None:
    """Take rclpy's SIGINT/SIGTERM handlers out and wait for its signal thread
    (``rclpy.signals.uninstall_signal_handlers`` joins it): the first step of a clean-up after
    rclpy ran, before anything is destroyed.

    rclpy's C handler only wakes that thread, which then triggers the executors' guard
    conditions and shuts the contexts down while the interrupted main thread goes on into its
    clean-up; destroying nodes, an executor or the context under it crashed a node process on
    shutdown under load (exit -11). From here on SIGTERM ends the process at once (what
    launchers escalate to when a clean-up hangs)."""
    uninstall_signal_handlers()


def run_node(factory: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Init rclpy, build the node, spin until shutdown (SIGINT/SIGTERM) or until the node asks to
    stop (:class:`FinishPolicy`, ``on_finish: exit``), clean up (:func:`run_nodes` of one)."""
    return run_nodes([factory], args)


def run_nodes(factories: Sequence[Callable[[], Node]], args: Sequence[str] | None = None) -> int:
    """Init rclpy, build the nodes (in order), spin them on one executor until shutdown
    (SIGINT/SIGTERM) or until every one of them asks to stop (:class:`FinishPolicy`,
    ``on_finish: exit``), clean up.

    Errors are one line on stderr, ``NAME: error: ...`` (NAME the failing factory's name), and
    the exit code follows the error's family (:func:`contgrasp_core.errors.exit_code`): a node
    that rejects its start-up parameters (rclpy's parameter exceptions, an
    :class:`~contgrasp_core.errors.InputError`) exits with code 2; a
    :class:`~contgrasp_core.errors.RunFailure` (e.g. a :class:`FatalNodeError`) while starting
    or spinning with code 1 (after the nodes' own clean-up); with several nodes the highest
    code. SIGINT/SIGTERM while a node is being built is a stop (exit code 0), whatever rclpy
    raised on the shut-down context. Any other exception is a bug and propagates with its
    traceback (exit code 1).
    """
    label = "+".join(getattr(f, "__name__", "node") for f in factories)
    argv = list(args) if args is not None else sys.argv
    unknown = rclpy.utilities.remove_ros_args(argv)[1:]
    if unknown:  # (e.g. a parameter given without --ros-args: it would be silently ignored)
        print(f"{label}: error: unrecognized arguments: {' '.join(unknown)} (parameters go after --ros-args: "
              "--ros-args -p NAME:=VALUE or --params-file FILE)", file=sys.stderr)
        return 2
    if threading.current_thread() is threading.main_thread():
        # (before rclpy.init: rclpy's own SIGINT handler shuts the context down, then chains to this one)
        signal.signal(signal.SIGINT, _interrupt_once)
    rclpy.init(args=argv)
    nodes: list[Node] = []
    code = 0
    try:
        for factory in factories:
            try:
                nodes.append(factory())
            except (
                rclpy.exceptions.InvalidParameterValueException,
                rclpy.exceptions.ParameterException,
                ContgraspError,
            ) as exc:
                code = exit_code(exc) if isinstance(exc, ContgraspError) else 2
                name = getattr(factory, "__name__", "node")
                print(f"{name}: error: {'invalid parameter: ' if code == 2 else ''}{one_line(exc)}", file=sys.stderr)
                return code
            except Exception as exc:
                if rclpy.ok():
                    raise
                # SIGINT/SIGTERM shut the context down while the node was being built (a launcher
                # stopping its graph because another node failed to start): a stop, not a failure
                raise ExternalShutdownException() from exc
        # (always the lean executor: CONTGRASP_EXECUTOR is the launcher's choice only; an
        # EventsExecutor in a node process hung the graph after resuming and ignored SIGINT/SIGTERM)
        executor = LeanExecutor()
        for node in nodes:
            executor.add_node(node)
        # (the executor's own failures are counted by the first node: contgrasp's nodes all have drops)
        spin = GuardedSpin(executor, getattr(nodes[0], "drops", None) or DropCounter(nodes[0]))
        while not all(getattr(node, "stop_requested", False) for node in nodes):  # (FinishPolicy: on_finish exit)
            spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ContgraspError as exc:  # a FatalNodeError from a callback, above all
        print(f"{label}: error: {one_line(exc)}", file=sys.stderr)
        code = exit_code(exc)
    finally:
        # A second SIGINT must not cut the clean-up short (a recorder finalising its file): a
        # terminal's Ctrl-C reaches every process and ros2 launch forwards one more to each child.
        # (SIGTERM still ends the process: what launchers escalate to when a clean-up hangs.)
        _ignore_interrupts()
        join_signal_thread()
        for node in nodes:
            node.destroy_node()
            code = max(code, int(getattr(node, "exit_code", 0)))  # a failure during the node's own clean-up
        if rclpy.ok():
            rclpy.shutdown()
    return code
