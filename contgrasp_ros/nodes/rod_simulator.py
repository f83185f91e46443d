"""rod_simulator: the planar Cosserat rod and the object (paper eq. (17)); publishes /clock, the rod
state (every step for the loop, every ``sample_period`` on the observers' sampled stream), the
object boundary, RViz markers and /diagnostics, and applies the couple control.

A thin wrapper of :class:`contgrasp_core.rod.session.LoopSession`, the core loop's stepping, so a
lock-step run equals the core-only run bit for bit; the stepping rules (step 0 waiting for the
loop's peers, lock-step, free-running, timeouts) are :mod:`contgrasp_ros.nodes.lockstep`. Services
``~/pause`` and ``~/reset``; a movable object takes wrench inputs (``~/apply_wrench``,
``/contgrasp/object_wrench``); the couple is eq. (19)'s or the holding law's hold (eq. (H4) of
docs/holding.md). Parameters, status, divergence limits and the movable object: docs/ros.md
("Nodes", "A movable object").
"""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import Header
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from contgrasp_core.errors import ContgraspError, interruption
from contgrasp_core.rod.body import MODES
from contgrasp_core.rod.closed_loop import MIN_CONTROL_PERIOD, ClosedLoopConfig
from contgrasp_core.rod.disturbance import KINDS, WrenchInput
from contgrasp_core.rod.session import DivergenceLimits, LoopSession, Observation, preload
from contgrasp_core.scenario import PAPER, motion_from_parameters, object_from_parameters, rod_system
from contgrasp_core.control import FeedbackExpansion
from contgrasp_core.control.hold_law import ShapeHold
from contgrasp_msgs.msg import CoupleControl, ObjectBoundary, RodState
from contgrasp_msgs.srv import ApplyWrench
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.cdr import Codec
from contgrasp_ros.plumbing.convert import (
    HeldShape,
    MessageError,
    boundary_to_msg,
    couple_arrays,
    rod_state_fields,
    wrench_arrays,
)
from contgrasp_ros.nodes.lockstep import Answered, CoupleWait, LockStep, Peers, StartGate, WallClock
from contgrasp_ros.plumbing.markers import scene_markers
from contgrasp_ros.nodes.rod_params import declare_rod_model
from contgrasp_ros.plumbing.diagnostics import Diagnostics
from contgrasp_ros.plumbing.faults import DropCounter, FatalNodeError, guarded, service_failure
from contgrasp_ros.plumbing.parameters import declare
from contgrasp_ros.plumbing.runtime import FinishPolicy, run_node, sim_time_by_default
from contgrasp_ros.plumbing.stamps import StampGate

FALLBACKS = ("hold", "zero")
# Lock-step: the timer polls the start gate every START_POLL_S until step 0 is out, then looks for
# a missed couple deadline every DEADLINE_POLL_S (at 5 ms it woke the simulator between almost
# every two steps of the loop; benchmarks/RESULTS.md, ros_loop).
START_POLL_S, DEADLINE_POLL_S = 0.005, 0.02


def _stamp(t: float) -> Time:
    sec = int(np.floor(t))
    return Time(sec=sec, nanosec=min(int(round((t - sec) * 1e9)), 999_999_999))


class RodSimulator(Node):
    """Owns the rod engine and the object; drives the closed loop in simulated time."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__("rod_simulator", **node_kwargs)
        sim_time_by_default(self)
        self.model = declare_rod_model(self)
        paper = PAPER.node_parameters("rod_simulator")
        obj = (
            declare(self, "object", paper["object"], "NAME[:PARAMS] in metres: circle[:R], ellipse[:a,b], "
                    "deformed[:R,amplitude,lobes,phase]; or 'outline' (with object_outline)", read_only=True),
            declare(self, "object_outline", paper["object_outline"], "with object 'outline': a CSV file, rows x, y [m]",
                    read_only=True),
            declare(self, "object_center", paper["object_center"], "object centre [x, y] (m)", read_only=True),
            declare(self, "object_angle", paper["object_angle"], "object orientation (rad, ellipse)", lo=-100.0, hi=100.0,
                    read_only=True),
        )
        # The run's settings shape the session when it starts: read-only (a change could only
        # take effect at a reset, which would be surprising).
        self.config = ClosedLoopConfig(
            duration=declare(self, "duration", paper["duration"], "simulated seconds at most [s]", lo=1e-6, hi=1e6, read_only=True),
            control_period=declare(self, "control_period", paper["control_period"], "control period [s]", lo=MIN_CONTROL_PERIOD, hi=10.0, read_only=True),
            dt=declare(self, "dt", paper["dt"], "integrator step [s]; 0 = the control period", lo=0.0, hi=10.0, read_only=True) or None,
            settle_speed=declare(self, "settle_speed", paper["settle_speed"], "settled when every node is slower [m/s]", lo=1e-12, hi=1e3, read_only=True),
            settle_hold=declare(self, "settle_hold", paper["settle_hold"], "for this long [s]", lo=1e-9, hi=1e6, read_only=True),
            min_time=declare(self, "min_time", paper["min_time"], "never settled before [s]", lo=0.0, hi=1e6, read_only=True),
        )
        declare(self, "couple_timeout", 10.0, "lock-step: wall seconds to wait for a couple", lo=1e-3, hi=3600.0)
        declare(self, "timeout_fallback", "hold", "lock-step timeout: 'hold' the last couple or apply 'zero'", choices=FALLBACKS)
        self.start_paused = declare(self, "start_paused", False, "wait for ~/pause(false) before the first step", read_only=True)
        declare(self, "marker_period", 0.05, "simulated seconds between RViz marker updates (0 = off)", lo=0.0, hi=1e6)
        declare(self, "clock_period", 0.01, "simulated seconds between /clock publications (0 = with every state; "
                "the first and the last state's always go out)", lo=0.0, hi=1e6)
        declare(self, "sample_period", 0.01, f"simulated seconds between states on {topics.ROD_STATE_SAMPLED}, the "
                "observers' stream (0 = every state; the first and the final state always)", lo=0.0, hi=1e6)
        self.lockstep = declare(self, "lockstep", True, "advance only when the couple for the current step arrived", read_only=True)
        couple_wait = declare(self, "couple_wait", 0.5, "free-running: the part of a control period a step waits after its "
                              "tick for the couple answering its state before it goes on with the newest couple (0 = no "
                              "wait; at most 0.9: the step must still fit in its period)", lo=0.0, hi=0.9, read_only=True)
        declare(self, "min_subscribers", 0, "publish the first state only once this many subscribers matched the "
                "rod state topics, per step and sampled together (a restarted simulator: its first state is not "
                "lost while they reconnect)", lo=0, hi=1000)
        self.gate = StartGate(
            wait_for_peers=declare(self, "wait_for_peers", True, "publish step 0 only once a rod-state subscriber "
                                   "(the sensor) and a couple publisher (the controller) are matched (also on the wall "
                                   "clock: a controller started later, plant.launch.py's, closes the loop)",
                                   read_only=True),
            timeout=declare(self, "peer_timeout", 30.0, "wall seconds to wait for the peers before publishing step 0 "
                            "anyway (0 = wait forever)", lo=0.0, hi=1e6, read_only=True),
        )
        self.rule = LockStep()
        self.taken = Answered()  # (lock-step: the couple taken last)
        assert self.config.control_period is not None  # (declared above with lo > 0)
        self.wall = WallClock(self.config.control_period)  # (free-running mode's deadlines)
        self.wait = CoupleWait(wait=not self.lockstep and couple_wait > 0)
        self.finish = FinishPolicy(self, watch_simulator=False)
        declare(self, "max_penetration_limit", 0.0,
                "the run fails when the rod surface is deeper inside the object than this [m]; 0 = the tip radius",
                lo=0.0, hi=100.0)
        declare(self, "max_kinetic_energy", 10.0, "the run fails when the rod's kinetic energy exceeds this [J]", lo=1e-12, hi=1e12)
        dynamics, disturbance = motion_from_parameters(self._declare_motion(paper))
        spec = object_from_parameters(*obj)
        self.boundary = spec.boundary()
        self.system = rod_system(self.model, spec, dynamics)  # (refuses an impossible start: check_start)
        self.wrenches = WrenchInput(disturbance)

        self.drops = DropCounter(self)
        self.stamps = StampGate(self)
        self.diagnostics = Diagnostics(self, self.drops, self._status_values, summary=self._status_summary)
        self.failure = ""
        # the loop's messages go out and in serialized (contgrasp_ros.plumbing.cdr: no conversion to Python
        # message objects); a typed couple passed to on_couple directly works too
        self.state_codec, self.couple_codec = Codec(RodState), Codec(CoupleControl)
        self.pub_clock = self.create_publisher(ClockMsg, topics.CLOCK, qos.STREAM)
        # (a peer that matches mid-run may be a restarted sensor or controller: LockStep.joined)
        self.pub_state = self.create_publisher(RodState, topics.ROD_STATE, qos.STREAM,
                                               event_callbacks=PublisherEventCallbacks(matched=self.on_matched))
        self.pub_sampled = self.create_publisher(RodState, topics.ROD_STATE_SAMPLED, qos.STREAM)
        self.pub_object = self.create_publisher(ObjectBoundary, topics.OBJECT, qos.LATCHED)
        self.pub_markers = self.create_publisher(MarkerArray, topics.MARKERS, qos.STREAM)
        self.sub_couple = self.create_subscription(CoupleControl, topics.COUPLE, self.on_couple, qos.STREAM, raw=True,
                                                   event_callbacks=SubscriptionEventCallbacks(matched=self.on_matched))
        if self.system.body is not None:
            self.pub_pose = self.create_publisher(PoseStamped, topics.OBJECT_POSE, qos.STREAM)
            self.pub_twist = self.create_publisher(TwistStamped, topics.OBJECT_TWIST, qos.STREAM)
        self.create_subscription(WrenchStamped, topics.OBJECT_WRENCH, self.on_wrench, qos.STREAM)
        self.create_service(SetBool, "~/pause", self.on_pause)
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.create_service(ApplyWrench, "~/apply_wrench", self.on_apply_wrench)
        self.pub_object.publish(boundary_to_msg(self.boundary, Header(frame_id="world")))
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        # the compiled kernels (numba's cache) load now, while the graph connects, not in the run's first steps
        preload(self.system, self.config)
        self._reset_session()
        self.paused = bool(self.start_paused)
        control_period = self.config.control_period
        assert control_period is not None  # (LoopSession, built above, requires it)
        period = control_period if not self.lockstep else START_POLL_S
        self._tick = self.create_timer(period, self.on_tick, clock=self._steady)
        # (free-running with a wait: armed by a tick whose couple is not in yet, see CoupleWait;
        # no timer otherwise: every timer joins every wait of the executor)
        self._wait_over = (self.create_timer(couple_wait * control_period, self.on_wait_over, clock=self._steady,
                                             autostart=False) if self.wait.wait else None)
        if not self.paused:
            self._publish_first_observation()

    def _declare_motion(self, paper: dict[str, Any]) -> dict[str, Any]:
        """Declare how the object moves and the scripted disturbance (read-only; the arrays and
        the combination are checked by :func:`~contgrasp_core.scenario.motion_from_parameters`)."""
        return {
            "object_mode": declare(self, "object_mode", paper["object_mode"], "how the object moves: fixed (the paper), "
                                   "spring (held to its start pose by object_stiffness / object_damping) or free",
                                   choices=MODES, read_only=True),
            "object_density": declare(self, "object_density", paper["object_density"], "areal density: mass and inertia "
                                      "from the enclosed area [kg/m^2]", lo=1e-12, hi=1e12, read_only=True),
            "object_mass": declare(self, "object_mass", paper["object_mass"], "mass (0 = from the density) [kg]",
                                   lo=0.0, hi=1e12, read_only=True),
            "object_inertia": declare(self, "object_inertia", paper["object_inertia"], "moment of inertia about the "
                                      "centroid (0 = from the density) [kg m^2]", lo=0.0, hi=1e12, read_only=True),
            "object_stiffness": declare(self, "object_stiffness", paper["object_stiffness"], "spring mode: stiffness to the "
                                        "start pose [N/m, N/m, N m/rad]", read_only=True),
            "object_damping": declare(self, "object_damping", paper["object_damping"], "spring mode: damping to the start "
                                      "pose [N s/m, N s/m, N m s/rad]", read_only=True),
            "disturbance_kind": declare(self, "disturbance_kind", paper["disturbance_kind"], "scripted wrench on a movable "
                                        "object: '' (none), step, ramp or pulse", choices=("", *KINDS), read_only=True),
            "disturbance_wrench": declare(self, "disturbance_wrench", paper["disturbance_wrench"], "its wrench: force at "
                                          "the centroid and torque about it [N, N, N m]", read_only=True),
            "disturbance_start": declare(self, "disturbance_start", paper["disturbance_start"], "its start [s]",
                                         lo=0.0, hi=1e9, read_only=True),
            "disturbance_duration": declare(self, "disturbance_duration", paper["disturbance_duration"],
                                            "ramp rise time / pulse length [s]", lo=0.0, hi=1e9, read_only=True),
        }

    @property
    def missed(self) -> int:
        """Deadlines missed in this run: couples that did not come in time (lock-step) or control
        periods the simulation fell behind the wall clock (free-running)."""
        return self.rule.missed if self.lockstep else self.wall.missed

    # ------------------------------------------------------------------ loop
    def _reset_session(self) -> None:
        self.session = LoopSession(self.system, self.config)
        self.last_couple: np.ndarray | FeedbackExpansion | ShapeHold = np.zeros(self.model.n_elements)
        self.law_ready = True  # (the last couple's law was not in transition: its next state may count as settled)
        self.rule.reset()
        self.taken.reset()
        self.wall.reset()
        self.wait.reset()
        self.next_t: dict[str, float] = {}  # simulated time of the next /clock, sampled state, markers
        self.loop_closed = False  # (free-running: the run's first couple arrived)
        self.failure = ""
        self.stamps.reset()
        self.wrenches.reset()
        self.finish.rearm()

    def limits(self) -> DivergenceLimits:
        """The divergence limits from the parameters (``max_penetration_limit`` 0 = the tip radius)."""
        pen = self.get_parameter("max_penetration_limit").value or self.model.radius_tip
        return DivergenceLimits(max_penetration=pen, max_kinetic_energy=self.get_parameter("max_kinetic_energy").value)

    def _fail(self, cause: str) -> None:
        """Stop the run: state ``failed``, the cause with the simulated time in ``message``."""
        self.failure = f"t = {float(self.session.state.t):.6g} s: {cause}"
        self.get_logger().error(f"simulation stopped: {self.failure}")
        self.rule.stop()
        self._publish_status()
        self.finish.done(True, f"the run failed at t = {float(self.session.state.t):.4g} s", self._publish_status)

    def _publish_observation(self) -> None:
        try:
            with np.errstate(all="ignore"):  # a diverging state overflows; it is reported below, not warned about
                obs = self.session.check_divergence(self.limits(), self.law_ready)
        except ContgraspError as exc:
            self._fail(str(exc))
            return
        header = Header(stamp=_stamp(obs.t), frame_id="world")
        wrench = self.wrenches.freeze(obs.k, obs.t)  # held over the period from this state
        centroid = None if self.system.body is None else self.system.body.centroid
        if self._due("clock_period", obs.t, final=True):
            self.pub_clock.publish(ClockMsg(clock=header.stamp))
        state = self.state_codec.encode(rod_state_fields(obs, header, centroid, wrench))
        self.pub_state.publish(state)  # (the loop's first: the sensor is waiting for it)
        self.sent = state  # (sent again while the loop has not closed: LockStep.resend_due)
        if self._due("sample_period", obs.t, final=True):
            self.pub_sampled.publish(state)
        self._publish_object_motion(obs, header)
        if (self.get_parameter("marker_period").value > 0 and self._due("marker_period", obs.t, final=False)
                and self.pub_markers.get_subscription_count() > 0):  # (built only for a viewer or a recorder)
            self.pub_markers.publish(scene_markers(self.boundary, obs, header, centroid))
        self.rule.published(time.monotonic())
        self.diagnostics.update(header.stamp)  # (a change of state, a missed deadline: at once)

    def _due(self, period_parameter: str, t: float, *, final: bool) -> bool:
        """Whether the state at simulated time ``t`` goes out on the stream published every
        ``period_parameter`` of simulated time (the first state of the run always; the final
        state too with ``final``); if so the stream's next time is ``t`` + the period."""
        if t + 1e-12 < self.next_t.get(period_parameter, 0.0) and not (final and self.session.finished):
            return False
        self.next_t[period_parameter] = t + self.get_parameter(period_parameter).value
        return True

    def _publish_object_motion(self, obs: Observation, header: Header) -> None:
        """A movable object's pose (centroid, rotation from the start pose) and twist."""
        body = self.system.body
        if body is None or obs.body is None:
            return
        x, y, psi = body.pose(obs.body.q)
        pose = PoseStamped(header=header)
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation.z, pose.pose.orientation.w = float(np.sin(0.5 * psi)), float(np.cos(0.5 * psi))
        self.pub_pose.publish(pose)
        twist = TwistStamped(header=header)
        twist.twist.linear.x, twist.twist.linear.y, twist.twist.angular.z = (float(v) for v in obs.body.v)
        self.pub_twist.publish(twist)

    def _status(self) -> str:
        if self.failure:
            return "failed"
        if self.session.finished:
            return "finished"
        return "paused" if self.paused else "running"

    def _status_values(self) -> tuple[int, str, dict[str, str]]:
        s = self.session
        values = {
            "state": self._status(),
            "step": str(s.k),
            "sim_time_s": repr(float(s.state.t)),
            "settled": "true" if s.settled else "false",
            "settle_time_s": repr(float(s.settle_time)) if s.settle_time is not None else "",
            "missed_deadlines": str(self.missed),
            "late_couples": str(self.wait.late),
            "dropped_messages": str(self.drops.total),
            "max_penetration": repr(float(s.max_penetration)),
            "validity": json.dumps(s.health.validity()),
            **{k: "" if v is None else repr(float(v)) for k, v in s.health.effort().items()},
            "message": self.failure,
        }
        return *self._status_summary(), values

    def _status_summary(self) -> tuple[int, str]:
        """The status's level and state (what the values' publication depends on)."""
        level = DiagnosticStatus.ERROR if self.failure else (DiagnosticStatus.WARN if self.missed else DiagnosticStatus.OK)
        return level, self._status()

    def _publish_status(self) -> None:
        self.diagnostics.publish(_stamp(float(self.session.state.t)))

    def _advance(self, couple: np.ndarray | FeedbackExpansion | ShapeHold) -> None:
        try:
            with np.errstate(all="ignore"):  # (as in _publish_observation)
                self.session.advance(couple, self.wrenches.freeze(self.session.k, float(self.session.state.t)))
        except FatalNodeError:
            raise
        except Exception as exc:  # Newton failure, or anything else: the state can no longer be trusted
            if (stop := interruption(exc)) is not None:  # (a Ctrl-C inside a compiled kernel: a stop)
                raise stop from None
            self._fail(str(exc) if isinstance(exc, ContgraspError) else f"{type(exc).__name__}: {exc}")
            return
        self.last_couple = couple
        self._publish_observation()
        if self.session.finished and not self.failure:
            self.rule.stop()
            s = self.session
            settled = f"settled at {s.settle_time:.4g} s" if s.settle_time is not None else "not settled"
            for broken in s.health.broken():
                self.get_logger().warn(f"the run left the model's validity, so it is not settled: {broken}")
            self.finish.done(False, f"finished at t = {s.state.t:.4g} s ({settled}, missed deadlines: {self.missed})",
                             self._publish_status)

    def _publish_first_observation(self) -> None:
        """The run's first state, once the peers are matched (:class:`~contgrasp_ros.nodes.lockstep.StartGate`)."""
        contact_publishers = self.count_publishers(topics.CONTACT)
        contact = min(contact_publishers, self.count_subscribers(topics.CONTACT))
        subscribers = self.pub_state.get_subscription_count() + self.pub_sampled.get_subscription_count()
        peers = Peers(subscribers, self.sub_couple.get_publisher_count(), contact, contact_publishers)
        go, line = self.gate.check(time.monotonic(), peers, self.get_parameter("min_subscribers").value)
        if line and "anyway" in line:  # (rclpy: one severity per logging call site)
            self.get_logger().warn(line)
        elif line:
            self.get_logger().info(line)
        if go:
            self._publish_observation()

    def _can_step(self) -> bool:
        return self.rule.started and not self.paused and not self.session.finished and not self.failure

    @guarded(topics.COUPLE)
    def on_couple(self, data: bytes | CoupleControl) -> None:
        """Validate a couple (serialized, or a message); in lock-step advance with the couple
        answering the current step."""
        if self.lockstep and self.taken.again(data):
            return  # a second answer to a state sent twice (LockStep.resend_due): taken already
        try:
            msg = self.couple_codec.message(data)
            step, s, taken, transition = couple_arrays(msg)
            n = len(taken.u if isinstance(taken, (FeedbackExpansion, HeldShape)) else taken)
            if n != self.model.n_elements or len(s) != n or np.max(np.abs(s - self.model.joint_s)) > 1e-12:
                raise MessageError(f"couple must be given at the {self.model.n_elements} joints s = k h", reason="wrong joints")
            u = taken.hold(self.model) if isinstance(taken, HeldShape) else taken
            if self.session.finished or self.failure:
                return  # the answer to the final state (or a failed run): nothing to do with it
            if self.lockstep and step != self.session.k:
                raise MessageError(f"couple for step {step} while waiting for step {self.session.k} "
                                   "(a late answer to a step that timed out, or a stale one)", reason="step mismatch")
            self.stamps.admit(topics.COUPLE, msg.header, step)
        except ContgraspError as exc:
            self.drops.drop_error(topics.COUPLE, exc)
            return
        self.law_ready = not transition
        if not self.lockstep:
            self.last_couple = u
            self.loop_closed = True
            if self.wait.couple(step) and self._can_step():
                self._end_wait()
                self._advance(u)
            return
        self.taken.keep(data)
        if self.rule.resent and not self.rule.closed:
            self.get_logger().info(f"the loop closed at step {step} after {self.rule.resent} re-send(s) of its state")
        elif self.rule.rejoined and self.rule.rejoin_resent:
            self.get_logger().info(f"the loop closed again at step {step} after {self.rule.rejoin_resent} re-send(s) "
                                   "of its state to the peer that joined")
        now, ended = self.rule.couple(u, self._can_step())
        if ended:
            self.get_logger().info(f"couples are back at step {step} after {ended} missed deadlines ({self.missed} in total)")
        if now is not None:
            self._advance(now)

    @guarded("graph")
    def on_matched(self, info: Any) -> None:
        """A reader of the rod state or a writer of couples matched (or left): one that joins a
        lock-step loop that has closed may be a sensor or controller restarted mid-run, which
        missed the awaited state (sent again: :meth:`LockStep.joined`)."""
        if self.lockstep and info.current_count_change > 0 and self.rule.closed and self.rule.waiting_since is not None:
            if not self.rule.rejoined:
                self.get_logger().info(f"a peer joined while step {self.session.k} waits for its couple: publishing it "
                                       f"again if unanswered for {self.rule.rejoin_resend:g} s, until the loop closes")
            self.rule.joined()

    @guarded("timer")
    def on_tick(self) -> None:
        if self.lockstep:
            poll_ns = int(1e9 * (DEADLINE_POLL_S if self.rule.started else START_POLL_S))
            if self._tick.timer_period_ns != poll_ns:
                self._tick.timer_period_ns = poll_ns
        if not self.rule.started and not self.paused and not self.failure:
            self._publish_first_observation()
        if not self._can_step():
            return
        if not self.lockstep:
            if not self.loop_closed:
                timeout = self.get_parameter("couple_timeout").value
                now = time.monotonic()
                if self.rule.waiting_since is not None and now - self.rule.waiting_since <= timeout:
                    self._resend_if_due(now)
                    return  # (the schedule starts with the first couple)
                self.get_logger().warn(f"no couple within {timeout:g} s of the first state: free-running without one")
                self.loop_closed = True
            if self.wait.expired():  # (a step still waiting for its couple: it goes now, this tick is lost)
                self._end_wait()
                self._advance(self.last_couple)
                return
            lost = self.wall.step(time.monotonic())
            if lost and self.wall.missed == lost:  # (the first time; the status says so at once: WARN)
                self.get_logger().warn(f"step {self.session.k} began {lost} control period(s) late: the simulation "
                                       "fell behind real time (each lost period is a missed deadline; not logged again)")
            if self.wait.tick(self.session.k):
                self._advance(self.last_couple)
            else:
                assert self._wait_over is not None  # (a tick waits only with couple_wait > 0)
                self._wait_over.reset()
            return
        now = time.monotonic()
        self._resend_if_due(now)
        if self.rule.tick(now, self.get_parameter("couple_timeout").value):
            fallback = self.get_parameter("timeout_fallback").value
            if self.rule.first_of_outage:  # once per outage; its length is reported when couples return
                self.get_logger().warn(
                    f"no couple for step {self.session.k} within the timeout: applying the '{fallback}' fallback "
                    f"until couples arrive again ({self.missed} missed deadlines so far)"
                )
            self._advance(self.last_couple if fallback == "hold" else np.zeros(self.model.n_elements))

    def _resend_if_due(self, now: float) -> None:
        """Until the loop's first couple, the awaited state again every ``LockStep.resend``
        seconds; after a peer joined, when unanswered (``LockStep.rejoin_resend``)."""
        if self.rule.resend_due(now):
            if self.rule.resent == 1 and not self.rule.closed:  # (once per run; the couple that closes the loop says how many)
                self.get_logger().info(f"step {self.session.k} unanswered after {self.rule.resend:g} s: publishing it "
                                       f"again every {self.rule.resend:g} s until the loop closes (a peer's reader may "
                                       "have matched after it went out)")
            self.pub_state.publish(self.sent)

    @guarded("timer")
    def on_wait_over(self) -> None:
        """Free-running: ``couple_wait`` periods passed since a tick without its couple: step with the newest."""
        self._end_wait()
        if self.wait.expired() and self._can_step():
            self._advance(self.last_couple)

    def _end_wait(self) -> None:
        """Disarm the couple wait's timer (the step goes, or the run pauses)."""
        if self._wait_over is not None:
            self._wait_over.cancel()

    @guarded(topics.OBJECT_WRENCH)
    def on_wrench(self, msg: WrenchStamped) -> None:
        """Validate a wrench and hold it on the object from the next control period on (its
        stamp is not used: the wrench acts from the next period whenever it was sent)."""
        try:
            wrench = wrench_arrays(msg)
            if self.system.body is None:
                raise MessageError("the object is fixed (object_mode): no wrench moves it", reason="object is fixed")
        except ContgraspError as exc:
            self.drops.drop_error(topics.OBJECT_WRENCH, exc)
            return
        self.wrenches.hold(wrench)

    # ------------------------------------------------------------------ services
    @guarded("~/apply_wrench", on_error=service_failure)
    def on_apply_wrench(self, req: ApplyWrench.Request, resp: ApplyWrench.Response) -> ApplyWrench.Response:
        """A step, ramp or pulse on the movable object from the next control period on."""
        resp.step = self.wrenches.next_step(self.session.k)
        if self.system.body is None:
            resp.success, resp.message = False, "the object is fixed (object_mode): no wrench moves it"
            return resp
        if self.session.finished or self.failure:
            resp.success, resp.message = False, f"the run is over ({self._status()}): ~/reset starts a new one"
            return resp
        try:
            self.wrenches.apply(req.kind, (float(req.wrench[0]), float(req.wrench[1]), float(req.wrench[2])), float(req.duration))
        except ContgraspError as exc:
            resp.success, resp.message = False, str(exc)
            return resp
        resp.success, resp.message = True, f"{req.kind} from step {resp.step}"
        return resp

    @guarded("~/pause", on_error=service_failure)
    def on_pause(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        self.paused = bool(req.data)
        if self.paused:
            self.wait.cancel()
            self._end_wait()
        else:
            if not self.rule.started:
                self._publish_first_observation()
            elif (u := self.rule.resume(time.monotonic())) is not None and self._can_step():
                self._advance(u)
            self.wall.restart()  # (free-running: the pause is not an overrun)
        self._publish_status()
        resp.success, resp.message = True, self._status()
        return resp

    @guarded("~/reset", on_error=service_failure)
    def on_reset(self, req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        self._reset_session()
        if not self.paused:
            self._publish_observation()
        resp.success, resp.message = True, "reset to the initial state"
        return resp


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros rod_simulator``."""
    return run_node(RodSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
