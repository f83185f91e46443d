"""Feedback control of continuum grasping (paper Sec. V-B).

* :mod:`.law` - the law (eq. (19)) and its static curvature form (eq. (20)), its gradient,
  Prop. 5.1's equilibrium, the Lyapunov function, the adaptive ``mu2`` of Appendix IV and the
  static closed-loop kinematics;
* :mod:`.gains` - the law's gains at the rod joints (:class:`FeedbackGains`, :func:`paper_gains`);
* :mod:`.rod_feedback` - the law on the rod engine: continuous state feedback, the sampled law at
  the joints and its first-order hold, the rod's rest under the law.
"""

from contgrasp_core.control.gains import FeedbackGains, paper_gains
from contgrasp_core.control.law import (
    CENTIMETRE,
    ClosedLoopKinematics,
    adaptive_mu2,
    closed_loop_kinematics,
    curvature_feedback,
    equilibrium_distance,
    feedback_couple,
    feedback_couple_gradient,
    lyapunov,
    lyapunov_rate,
)
from contgrasp_core.control.rod_feedback import (
    FeedbackExpansion,
    HeldExpansion,
    StateFeedback,
    feedback_at_joints,
)

__all__ = [
    "CENTIMETRE",
    "ClosedLoopKinematics",
    "adaptive_mu2",
    "closed_loop_kinematics",
    "curvature_feedback",
    "equilibrium_distance",
    "feedback_couple",
    "feedback_couple_gradient",
    "lyapunov",
    "lyapunov_rate",
    "FeedbackGains",
    "paper_gains",
    "FeedbackExpansion",
    "HeldExpansion",
    "StateFeedback",
    "feedback_at_joints",
]
