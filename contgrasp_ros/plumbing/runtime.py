"""A node's life: its executor (:func:`make_executor`), simulated time by default, the end of a
run (:class:`FinishPolicy`, ``on_finish``), the object it follows (:class:`ObjectTracker`), the
guarded spin and main() (:func:`run_node`: signals, exit codes, clean-up).

Every contgrasp node runs through these, so they start, stop and fail the same way (docs/ros.md,
"Nodes"; docs/RELIABILITY.md). Its parameters, faults, stamps and status are those of
:mod:`.parameters`, :mod:`.faults`, :mod:`.stamps` and :mod:`.diagnostics`.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.signals import uninstall_signal_handlers

from contgrasp_core.boundary import Boundary
from contgrasp_core.errors import ContgraspError, exit_code, one_line
from contgrasp_ros.plumbing import topics
from contgrasp_ros.plumbing.executor import LeanExecutor
from contgrasp_ros.plumbing.faults import DropCounter, guarded
from contgrasp_ros.plumbing.parameters import declare
from contgrasp_ros.plumbing.stamps import StampGate

__all__ = [
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
