"""grasp_controller: contact state -> internal couple control u(s) (paper eq. (19), or the
holding law of docs/holding.md, or its planned playback).

A thin wrapper of the core's laws, chosen by the read-only ``law`` parameter: the paper's through
:func:`contgrasp_core.control.feedback_at_joints`,
:class:`contgrasp_core.control.hold_law.HoldController` ((H1)-(H6); ``hold_<name>`` parameters),
or :class:`contgrasp_core.holding.plan.PlannedHold` (planned at start on the ``object*`` copy).
The same functions the core-only loop calls, so a lock-step ROS run reproduces it exactly. A
state sent twice is answered with the couple already published
(:class:`~contgrasp_ros.nodes.lockstep.Answered`). docs/ros.md ("Any law").
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node

from contgrasp_core.control import FeedbackGains, feedback_at_joints, paper_gains
from contgrasp_core.control.hold_law import LAWS, HoldController, HoldLawSettings, Law, ShapeHold
from contgrasp_core.errors import ContgraspError, InvalidParameterError
from contgrasp_core.rod.closed_loop import MIN_CONTROL_PERIOD
from contgrasp_core.scenario import HOLD_PREFIX, OBJECT_PARAMETERS, PAPER, object_from_parameters
from contgrasp_msgs.msg import ContactState, CoupleControl
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.cdr import Codec
from contgrasp_ros.plumbing.convert import ContactArrays, MessageError, contact_arrays, couple_fields, require_finite
from contgrasp_ros.nodes.lockstep import Answered
from contgrasp_ros.nodes.rod_params import declare_rod_model
from contgrasp_ros.plumbing.diagnostics import Diagnostics
from contgrasp_ros.plumbing.faults import DropCounter, guarded
from contgrasp_ros.plumbing.parameters import add_parameter_check, declare
from contgrasp_ros.plumbing.runtime import FinishPolicy, run_node, sim_time_by_default
from contgrasp_ros.plumbing.stamps import StampGate

if TYPE_CHECKING:
    from contgrasp_core.holding.plan import HoldPlan

GAIN_PARAMETERS = ("mu1", "mu2", "adaptive_mu2", "object_radius", "length_unit")
MU2_LIMIT = 1e6  # |mu2| in law units, given or adaptive


class GraspController(Node):
    """Evaluates the feedback law on every contact state and publishes the couple."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__("grasp_controller", **node_kwargs)
        sim_time_by_default(self)
        self.model = declare_rod_model(self)
        paper = PAPER.node_parameters("grasp_controller")
        declare(self, "mu1", paper["mu1"], "gain mu1 > 0 of eq. (19)", lo=1e-9, hi=1e6)
        declare(self, "mu2", paper["mu2"], "gain mu2 in law length units (used when adaptive_mu2 is false)", lo=-MU2_LIMIT, hi=MU2_LIMIT)
        declare(self, "adaptive_mu2", paper["adaptive_mu2"], "use mu2(s) = r(s) - 1/(r_obj + r(s)) (paper App. IV)")
        declare(self, "object_radius", paper["object_radius"], "object radius r_obj for the adaptive mu2 [m]", lo=1e-9, hi=1e3)
        declare(self, "length_unit", paper["length_unit"], "metres per length unit of the law (paper: cm)", lo=1e-9, hi=1e3)
        self.law_name = declare(self, "law", paper["law"], "the closed loop's law: paper (eq. (19)), hold (the "
                                "planned hold) or reactive (docs/holding.md)", choices=LAWS, read_only=True)
        self.period = declare(self, "control_period", paper["control_period"], "the simulator's control period: the "
                              "holding law's phases run in time [s]", lo=MIN_CONTROL_PERIOD, hi=10.0, read_only=True)
        self.hold_settings = HoldLawSettings(**{
            f.name: declare(self, f"{HOLD_PREFIX}{f.name}", paper[f"{HOLD_PREFIX}{f.name}"],
                            f"holding law: {f.name} (contgrasp_core.control.hold_law.HoldLawSettings)", read_only=True)
            for f in fields(HoldLawSettings)})
        o = {name: declare(self, name, paper[name], f"the simulator's {name}, copied: law hold plans on the object",
                           read_only=True) for name in OBJECT_PARAMETERS}
        # (checked under every law: a nonsense copy stops the node at start, as the simulator's own)
        self.object_spec = object_from_parameters(o["object"], o["object_outline"], o["object_center"], o["object_angle"])
        self.plan = self._plan() if self.law_name == "hold" else None  # (before the subscription: no state waits on it)
        self.hold: Law | None = None  # (the holding law's, or the plan's playback's, state in this run)
        self.hold_step = -1  # (the step it answered last)
        self.drops = DropCounter(self)
        self.stamps = StampGate(self)
        self.diagnostics = Diagnostics(self, self.drops, self._status_values, summary=self._status_summary)
        self.finish = FinishPolicy(self, watch_simulator=True)
        self.gains = self._gains({n: self.get_parameter(n).value for n in GAIN_PARAMETERS})
        add_parameter_check(self, self._check_gains)
        self.add_post_set_parameters_callback(self.drops.guard("parameters", self._refresh))
        # the loop's messages go in and out serialized (contgrasp_ros.plumbing.cdr); a typed message
        # passed to on_contact directly works too
        self.contact_codec, self.couple_codec = Codec(ContactState), Codec(CoupleControl)
        self.answered = Answered()  # (the contact state answered last and its couple)
        self.pub = self.create_publisher(CoupleControl, topics.COUPLE, qos.STREAM)
        self.create_subscription(ContactState, topics.CONTACT, self.on_contact, qos.STREAM, raw=True)

    def _gains(self, p: dict[str, Any]) -> FeedbackGains:
        if p["adaptive_mu2"]:
            gains = paper_gains(self.model, p["object_radius"], mu1=p["mu1"], length_unit=p["length_unit"])
        else:
            gains = FeedbackGains(mu1=p["mu1"], mu2=p["mu2"], length_unit=p["length_unit"])
        if not np.all(np.abs(gains.mu2) <= MU2_LIMIT):
            raise InvalidParameterError(f"mu2 beyond +-{MU2_LIMIT:g} law units (adaptive with object_radius "
                                 f"{p['object_radius']} m, length_unit {p['length_unit']} m?)")
        return gains

    def _check_gains(self, values: dict[str, Any]) -> str | None:
        try:
            self._gains(values)
        except ContgraspError as exc:
            return f"unusable gains: {exc}"
        return None

    def _refresh(self, _params: object) -> None:
        self.gains = self._gains({n: self.get_parameter(n).value for n in GAIN_PARAMETERS})

    @guarded(topics.CONTACT)
    def on_contact(self, data: bytes | ContactState) -> None:
        """Validate a contact state (serialized, or a message) and answer it with the couple
        (echoing its stamp and step)."""
        if self.answered.again(data):  # (the answer to a state sent again: the simulator may not have had the couple)
            self.pub.publish(self.answered.answer)
            return
        try:
            msg = self.contact_codec.message(data)
            c = contact_arrays(msg)
            if len(c.s) != self.model.n_elements + 1:
                raise MessageError(
                    f"contact state has {len(c.s)} nodes; the controller's rod has {self.model.n_elements + 1}",
                    reason="wrong node count",
                )
            self.stamps.admit(topics.CONTACT, msg.header, c.step)
            command, transition = (self.gains, False) if self.law_name == "paper" else self._hold_command(c)
            if isinstance(command, ShapeHold):
                u: Any = command
                require_finite("the hold", command.kappa_ref)
            else:
                u = feedback_at_joints(self.model, command, c.rho, c.alpha)
                require_finite("the couple", u.u, u.g_rho, u.g_alpha)
        except ContgraspError as exc:
            self.drops.drop_error(topics.CONTACT, exc)
            return
        self.diagnostics.update()  # (at once when the law's phase changed: before the couple it gave)
        out = self.couple_codec.encode(couple_fields(self.model.joint_s, u, msg.header, c.step, transition))
        self.pub.publish(out)
        self.answered.keep(data, out)

    def _plan(self) -> HoldPlan:
        """The planned hold's plan (:func:`contgrasp_core.holding.plan.plan_hold`) of the scenario
        this node's parameters describe: its rod, the object copy, its gains and hold settings
        (the engine imported here, under law hold only)."""
        from contgrasp_core.holding.plan import plan_hold
        from contgrasp_core.scenario import GainSettings

        p = self.get_parameter
        gains = GainSettings(mu1=p("mu1").value, mu2=p("mu2").value, adaptive_mu2=p("adaptive_mu2").value,
                             object_radius=p("object_radius").value, length_unit=p("length_unit").value)
        return plan_hold(replace(PAPER, rod=self.model, object=self.object_spec, gains=gains, law="hold", hold_law=self.hold_settings))

    @property
    def law_phase(self) -> str:
        """The holding law's (or the plan's playback's) phase in this run ('' under the paper's
        law and before the first state)."""
        return "" if self.hold is None else str(getattr(self.hold, "phase", ""))

    def _status_values(self) -> tuple[int, str, dict[str, str]]:
        """The status with the law and its phase (``law``, ``law_phase``), what the run summaries report."""
        return *self._status_summary(), {"law": self.law_name, "law_phase": self.law_phase}

    def _status_summary(self) -> tuple[int, str]:
        """OK (WARN once messages were dropped: :class:`Diagnostics`) and the law, its phase and the drops."""
        phase = f", phase {self.law_phase}" if self.law_phase else ""
        dropped = f"; {self.drops.total} messages dropped" if self.drops.total else ""
        return DiagnosticStatus.OK, f"law {self.law_name}{phase}{dropped}"

    def _hold_command(self, c: ContactArrays) -> tuple[FeedbackGains | ShapeHold, bool]:
        """The holding law's command for the contact state ``c`` and whether the law is still in
        transition (:meth:`HoldController.command` over the control periods since the last
        state; a fresh law for a new run)."""
        if c.theta.size == 0:
            raise MessageError("the holding law senses the arm's shape: the contact state has no theta and kappa",
                               reason="no arm shape")
        if self.hold is None or c.step <= self.hold_step:  # (step 0 again, or below: the simulator's new run)
            p = self.get_parameter
            if self.plan is not None:
                from contgrasp_core.holding.plan import PlannedHold

                self.hold = PlannedHold(self.model, self.plan, self.hold_settings)
            else:
                self.hold = HoldController(self.model, p("object_radius").value, self.hold_settings, p("length_unit").value)
            self.hold_step = c.step - 1
        command = self.hold.command(c.rho, c.alpha, c.theta, c.kappa[:-1], self.period * (c.step - self.hold_step))
        self.hold_step = c.step
        return command, not self.hold.holding


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros grasp_controller``."""
    return run_node(GraspController, args)


if __name__ == "__main__":
    raise SystemExit(main())
