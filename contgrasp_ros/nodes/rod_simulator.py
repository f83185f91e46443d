"""rod_simulator: the planar Cosserat rod and the object; publishes /clock, the rod state, the
object boundary (transient-local), RViz markers and /diagnostics; applies the couple control.

Thin wrapper of :class:`contgrasp_core.rod.session.LoopSession` (the same stepping the
core-only closed loop uses). Lock-step mode (default): state k is published and the rod
advances only when the couple stamped with step k arrives; after ``couple_timeout`` wall
seconds the configured fallback (``hold`` the last couple or apply ``zero``) is used, the miss
is counted and a warning logged. Free-running mode advances every ``control_period`` of wall
time with the latest couple. Services: ``~/pause`` (std_srvs/SetBool: true pauses, false
resumes) and ``~/reset`` (std_srvs/Trigger).
"""

from __future__ import annotations

import time

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import Header
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from contgrasp_core.errors import ContgraspError, InvalidParameterError
from contgrasp_core.rod import Obstacle, RodSystem
from contgrasp_core.rod.closed_loop import ClosedLoopConfig
from contgrasp_core.rod.session import FeedbackExpansion, LoopSession, Observation, boundary_from_spec
from contgrasp_msgs.msg import CoupleControl, ObjectBoundary, RodState
from contgrasp_ros import qos
from contgrasp_ros.convert import boundary_to_msg, couple_arrays
from contgrasp_ros.markers import scene_markers
from contgrasp_ros.nodes.rod_params import declare_rod_model
from contgrasp_ros.runtime import DropCounter, declare, run_node

FALLBACKS = ("hold", "zero")


def _stamp(t: float) -> Time:
    sec = int(np.floor(t))
    return Time(sec=sec, nanosec=min(int(round((t - sec) * 1e9)), 999_999_999))


class RodSimulator(Node):
    """Owns the rod engine and the object; drives the closed loop in simulated time."""

    def __init__(self, **node_kwargs: object) -> None:
        super().__init__("rod_simulator", **node_kwargs)  # type: ignore[arg-type]
        self.model = declare_rod_model(self)
        kind = declare(self, "object_kind", "circle", "circle | ellipse | deformed_circle", read_only=True)
        params = declare(
            self, "object_params", [0.025, 0.08, 0.08],
            "circle [R, cx, cy]; ellipse [a, b, cx, cy, angle]; deformed_circle [R, amplitude, lobes, phase, cx, cy] (m, rad)",
            read_only=True,
        )
        self.config = ClosedLoopConfig(
            duration=declare(self, "duration", 20.0, "simulated seconds at most [s]", lo=1e-6, hi=1e6),
            control_period=declare(self, "control_period", 0.01, "control period [s]", lo=1e-6, hi=10.0, read_only=True),
            dt=declare(self, "dt", 0.0, "integrator step [s]; 0 = the control period", lo=0.0, hi=10.0, read_only=True) or None,
            settle_speed=declare(self, "settle_speed", 2e-4, "settled when every node is slower [m/s]", lo=1e-12, hi=1e3),
            settle_hold=declare(self, "settle_hold", 0.5, "for this long [s]", lo=1e-9, hi=1e6),
            min_time=declare(self, "min_time", 1.0, "never settled before [s]", lo=0.0, hi=1e6),
        )
        self.lockstep = declare(self, "lockstep", True, "advance only when the couple for the current step arrived", read_only=True)
        declare(self, "couple_timeout", 10.0, "lock-step: wall seconds to wait for a couple", lo=1e-3, hi=3600.0)
        declare(self, "timeout_fallback", "hold", "lock-step timeout: 'hold' the last couple or apply 'zero'")
        self.start_paused = declare(self, "start_paused", False, "wait for ~/pause(false) before the first step")
        declare(self, "marker_period", 0.05, "simulated seconds between RViz marker updates (0 = off)", lo=0.0, hi=1e6)
        self.add_on_set_parameters_callback(self._check_params)
        if self.get_parameter("timeout_fallback").value not in FALLBACKS:
            raise InvalidParameterError(f"timeout_fallback must be one of {FALLBACKS}")
        self.boundary = boundary_from_spec(kind, params)
        self.system = RodSystem(self.model, Obstacle(self.boundary))

        self.drops = DropCounter(self)
        self.missed = 0
        self.failure = ""
        self.pub_clock = self.create_publisher(ClockMsg, "/clock", qos.STREAM)
        self.pub_state = self.create_publisher(RodState, qos.TOPIC_ROD_STATE, qos.STREAM)
        self.pub_object = self.create_publisher(ObjectBoundary, qos.TOPIC_OBJECT, qos.LATCHED)
        self.pub_markers = self.create_publisher(MarkerArray, qos.TOPIC_MARKERS, qos.STREAM)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.STREAM)
        self.create_subscription(CoupleControl, qos.TOPIC_COUPLE, self.on_couple, qos.STREAM)
        self.create_service(SetBool, "~/pause", self.on_pause)
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.pub_object.publish(boundary_to_msg(self.boundary, Header(frame_id="world")))
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._reset_session()
        self.paused = bool(self.start_paused)
        period = self.config.control_period if not self.lockstep else 0.005
        self.create_timer(period, self.on_tick, clock=self._steady)
        if not self.paused:
            self._publish_observation()

    # ------------------------------------------------------------------ parameters
    def _check_params(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "timeout_fallback" and p.value not in FALLBACKS:
                return SetParametersResult(successful=False, reason=f"timeout_fallback must be one of {FALLBACKS}")
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ loop
    def _reset_session(self) -> None:
        self.session = LoopSession(self.system, self.config)
        self.last_couple: np.ndarray | FeedbackExpansion = np.zeros(self.model.n_elements)
        self.pending: np.ndarray | FeedbackExpansion | None = None
        self.waiting_since: float | None = None
        self.published = False
        self.next_marker_t = 0.0
        self.failure = ""

    def _publish_observation(self) -> None:
        obs = self.session.observe()
        header = Header(stamp=_stamp(obs.t), frame_id="world")
        self.pub_clock.publish(ClockMsg(clock=header.stamp))
        self.pub_state.publish(
            RodState(
                header=header, step=obs.k, s=obs.s.tolist(), x=obs.x[:, 0].tolist(), y=obs.x[:, 1].tolist(),
                theta=obs.theta.tolist(), kappa=obs.kappa.tolist(), radius=obs.radius.tolist(),
                vx=obs.v[:, 0].tolist(), vy=obs.v[:, 1].tolist(), kinetic_energy=obs.kinetic_energy,
                max_penetration=obs.penetration,
            )
        )
        period = self.get_parameter("marker_period").value
        if period > 0 and obs.t + 1e-12 >= self.next_marker_t:
            self.next_marker_t = obs.t + period
            self.pub_markers.publish(scene_markers(self.boundary, obs, header))
        self.published = True
        self.waiting_since = time.monotonic()
        self._publish_status(obs)

    def _status(self) -> str:
        if self.failure:
            return "failed"
        if self.session.finished:
            return "finished"
        return "paused" if self.paused else "running"

    def _publish_status(self, obs: Observation | None = None) -> None:
        s = self.session
        values = {
            "state": self._status(),
            "step": str(s.k),
            "sim_time_s": repr(float(s.state.t)),
            "settled": "true" if s.settled else "false",
            "settle_time_s": repr(float(s.settle_time)) if s.settle_time is not None else "",
            "missed_deadlines": str(self.missed),
            "dropped_messages": str(self.drops.total),
            "max_penetration": repr(float(s.max_penetration)),
            "message": self.failure,
        }
        level = DiagnosticStatus.ERROR if self.failure else (DiagnosticStatus.WARN if self.missed else DiagnosticStatus.OK)
        st = DiagnosticStatus(level=level, name="rod_simulator", message=values["state"], hardware_id="contgrasp",
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
        self.pub_diag.publish(DiagnosticArray(header=Header(stamp=_stamp(float(s.state.t))), status=[st]))

    def _advance(self, couple: np.ndarray | FeedbackExpansion) -> None:
        try:
            self.session.advance(couple)
        except ContgraspError as exc:
            self.failure = f"t = {self.session.state.t:.6g} s: {exc}"
            self.get_logger().error(f"simulation stopped: {self.failure}")
            self.waiting_since = None
            self._publish_status()
            return
        self.last_couple = couple
        self._publish_observation()
        if self.session.finished:
            self.waiting_since = None
            self.get_logger().info(
                f"finished at t = {self.session.state.t:.4g} s (settled: {self.session.settled}, missed deadlines: {self.missed})"
            )

    def _can_step(self) -> bool:
        return self.published and not self.paused and not self.session.finished and not self.failure

    def on_couple(self, msg: CoupleControl) -> None:
        try:
            step, s, u = couple_arrays(msg)
            n = len(u.u) if isinstance(u, FeedbackExpansion) else len(u)
            if n != self.model.n_elements or not np.allclose(s, self.model.joint_s, rtol=0, atol=1e-12):
                raise ContgraspError(f"couple must be given at the {self.model.n_elements} joints s = k h")
        except ContgraspError as exc:
            self.drops.drop(qos.TOPIC_COUPLE, str(exc))
            return
        if not self.lockstep:
            self.last_couple = u
            return
        if step != self.session.k or self.session.finished:
            return  # a late answer to a step that already timed out
        if self._can_step():
            self._advance(u)
        else:
            self.pending = u

    def on_tick(self) -> None:
        if not self._can_step():
            return
        if not self.lockstep:
            self._advance(self.last_couple)
            return
        if self.waiting_since is not None and time.monotonic() - self.waiting_since > self.get_parameter("couple_timeout").value:
            self.missed += 1
            fallback = self.get_parameter("timeout_fallback").value
            self.get_logger().warn(
                f"no couple for step {self.session.k} within the timeout: applying the '{fallback}' fallback "
                f"({self.missed} missed deadlines so far)",
                throttle_duration_sec=2.0,
            )
            self._advance(self.last_couple if fallback == "hold" else np.zeros(self.model.n_elements))

    # ------------------------------------------------------------------ services
    def on_pause(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        self.paused = bool(req.data)
        if not self.paused:
            if not self.published:
                self._publish_observation()
            elif self.pending is not None and self._can_step():
                u, self.pending = self.pending, None
                self._advance(u)
            else:
                self.waiting_since = time.monotonic()
        self._publish_status()
        resp.success, resp.message = True, self._status()
        return resp

    def on_reset(self, req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        self._reset_session()
        self.missed = 0
        if not self.paused:
            self._publish_observation()
        resp.success, resp.message = True, "reset to the initial state"
        return resp


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros rod_simulator``."""
    return run_node(RodSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
