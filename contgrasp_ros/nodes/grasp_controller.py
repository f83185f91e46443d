"""grasp_controller: contact state -> internal couple control u(s) (paper eq. (19)).

Thin wrapper of :func:`contgrasp_core.rod.session.feedback_at_joints`: the same function the
core-only closed loop calls, so a lock-step ROS run reproduces it exactly. Gains (mu1, mu2 or
the adaptive mu2 of Appendix IV, the law's length unit) are parameters; a change takes effect
at the next contact message (a set that gives unusable gains is refused). The rod geometry
parameters (read-only) must match the simulator's. Malformed contact states, bad stamps and
states of another rod size are dropped and counted (``/diagnostics``). A contact state taken
again (the answer to a rod state the simulator re-sent) is answered again with the couple
published for it, not computed twice (:class:`~contgrasp_ros.nodes.lockstep.Answered`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.node import Node

from contgrasp_core.control import FeedbackGains, feedback_at_joints, paper_gains
from contgrasp_core.errors import ContgraspError, InvalidParameterError
from contgrasp_core.scenario import PAPER
from contgrasp_msgs.msg import ContactState, CoupleControl
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.cdr import Codec
from contgrasp_ros.plumbing.convert import MessageError, contact_arrays, couple_fields, require_finite
from contgrasp_ros.nodes.lockstep import Answered
from contgrasp_ros.nodes.rod_params import declare_rod_model
from contgrasp_ros.plumbing.runtime import (
    Diagnostics,
    DropCounter,
    FinishPolicy,
    StampGate,
    add_parameter_check,
    declare,
    guarded,
    run_node,
    sim_time_by_default,
)

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
        self.drops = DropCounter(self)
        self.stamps = StampGate(self)
        self.diagnostics = Diagnostics(self, self.drops)
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
            u = feedback_at_joints(self.model, self.gains, c.rho, c.alpha)
            require_finite("the couple", u.u, u.g_rho, u.g_alpha)
        except ContgraspError as exc:
            self.drops.drop_error(topics.CONTACT, exc)
            return
        out = self.couple_codec.encode(couple_fields(self.model.joint_s, u, msg.header, c.step))
        self.pub.publish(out)
        self.answered.keep(data, out)


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros grasp_controller``."""
    return run_node(GraspController, args)


if __name__ == "__main__":
    raise SystemExit(main())
