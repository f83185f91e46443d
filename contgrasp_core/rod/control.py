"""The feedback couple as a function of the rod state, for implicit (continuous) feedback.

With a zero-order hold the couple of eq. dynamic_feedback is sampled every control period and
held; the loop then inherits a sampling-rate stability limit (the law acts at the element scale,
where the tapered tip has bending frequencies of thousands of rad/s). :class:`StateFeedback`
instead evaluates the law inside every Newton iteration of the implicit step, at the new state,
and supplies its derivative ``du/dtheta`` to the Newton matrix, so the continuous-time loop of
paper Prop. 2 is integrated with the same unconditional stability as the elastic forces.

Sensing is at the joints ``s_k = k h`` (the clamp and the internal nodes; the tip carries no
couple): ``rho_k`` the signed distance of node ``k`` to the boundary, ``alpha_k = phi + pi/2 -
theta_k`` with ``theta_k`` the mean angle of the adjacent elements (eq. rho_alpha_definition).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contgrasp_core.feedback import CENTIMETRE, adaptive_mu2, feedback_couple, feedback_couple_gradient
from contgrasp_core.rod import chain
from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.obstacle import Obstacle

__all__ = ["FeedbackGains", "paper_gains", "StateFeedback", "JointSensing", "sense_joints", "joint_couple_jacobian"]


@dataclass(frozen=True)
class FeedbackGains:
    """Gains of eq. dynamic_feedback at the rod joints: ``mu1`` (scalar or (N,)), ``mu2`` (scalar
    or (N,), law units) and ``length_unit`` (metres per law unit, cm by default)."""

    mu1: float | np.ndarray = 1.0
    mu2: float | np.ndarray = 0.0
    length_unit: float = CENTIMETRE


def paper_gains(model: RodModel, object_radius: float, *, mu1: float = 1.0,
                length_unit: float = CENTIMETRE) -> FeedbackGains:
    """``mu1 = 1`` and the adaptive ``mu2(s) = r(s) - 1/(r_obj + r(s))`` (appendix) at the joints."""
    return FeedbackGains(mu1=mu1, mu2=adaptive_mu2(model.radius(model.joint_s), object_radius,
                                                   length_unit=length_unit), length_unit=length_unit)


@dataclass(frozen=True)
class StateFeedback:
    """``u(theta)`` of eq. dynamic_feedback sensed on the rod itself, with its Jacobian."""

    model: RodModel
    obstacle: Obstacle
    gains: FeedbackGains

    def couple(self, theta: np.ndarray) -> np.ndarray:
        """The couple at the joints (N,) in N m for element angles ``theta``."""
        return self.couple_and_jacobian(theta, jacobian=False)[0]

    def couple_and_jacobian(self, theta: np.ndarray, *, jacobian: bool = True, nodes: np.ndarray | None = None,
                            normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """``u`` (N,) and ``du/dtheta`` (N, N) (:func:`joint_couple_jacobian`). ``nodes``
        (N+1, 2) and element ``normals`` (N, 2) may be passed when already computed."""
        m, g = self.model, self.gains
        js = sense_joints(m, self.obstacle, theta, nodes)
        ei = m.joint_ei
        u = feedback_couple(js.rho, js.alpha, ei, g.mu1, g.mu2, length_unit=g.length_unit)
        if not jacobian:
            return u, None
        g_rho, g_alpha = feedback_couple_gradient(js.rho, js.alpha, ei, g.mu1, g.mu2, length_unit=g.length_unit)
        b = chain.frames(theta)[1] if normals is None else normals
        return u, joint_couple_jacobian(m, g_rho, g_alpha, js, b)


@dataclass(frozen=True)
class JointSensing:
    """(rho, alpha) at the N joints (eq. rho_alpha_definition; alpha not wrapped: it is used in
    differences and trigonometric functions), the outward normal at the foot (N, 2) and
    ``foot_turn = kappa_o / (1 + rho kappa_o)`` (1/m), the rate at which the foot's tangent angle
    turns per unit tangential motion of the joint (0 where ``1 + rho kappa_o`` is not safely
    positive: there the closest point is degenerate, paper Sec. III ``nu_o``)."""

    rho: np.ndarray
    alpha: np.ndarray
    normal_out: np.ndarray
    foot_turn: np.ndarray


def sense_joints(model: RodModel, obstacle: Obstacle, theta: np.ndarray, nodes: np.ndarray | None = None) -> JointSensing:
    """Sensing at the joints ``s_k = k h``, k = 0..N-1 (see :class:`JointSensing`)."""
    x = (chain.nodes(model, theta) if nodes is None else nodes)[:-1]
    th_n = chain.node_angles(model, theta)[:-1]
    pr = obstacle.project(x)
    den = 1.0 + pr.signed_distance * pr.kappa_o
    turn = np.where(den > 0.05, pr.kappa_o / np.where(den > 0.05, den, 1.0), 0.0)
    return JointSensing(rho=pr.signed_distance, alpha=pr.phi + 0.5 * np.pi - th_n, normal_out=pr.normal_out, foot_turn=turn)


def joint_couple_jacobian(model: RodModel, g_rho: np.ndarray, g_alpha: np.ndarray, sensing: JointSensing,
                          b: np.ndarray) -> np.ndarray:
    """``du/dtheta`` (N, N) of a joint couple with partials ``g_rho``, ``g_alpha`` (N,).

    Node k moves by ``h b_l`` per unit ``theta_l``, ``l < k``: ``d rho_k / d theta_l = h n_k . b_l``
    and the foot's tangent angle turns by ``h foot_turn_k t_k . b_l`` (``t_k`` the boundary
    tangent at the foot). The node angle is the mean of the adjacent elements:
    ``d alpha_k / d theta_{k-1} = d alpha_k / d theta_k = -1/2``.
    """
    n_out = sensing.normal_out
    tangent = np.stack([-n_out[:, 1], n_out[:, 0]], axis=1)
    direction = g_rho[:, None] * n_out + (g_alpha * sensing.foot_turn)[:, None] * tangent
    du = model.h * np.tril(direction @ b.T, -1)
    coef = -0.5 * g_alpha
    k = np.arange(1, model.n_elements)
    du[k, k] += coef[1:]
    du[k, k - 1] += coef[1:]
    return du
