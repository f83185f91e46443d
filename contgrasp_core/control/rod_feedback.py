"""The feedback law applied to the rod engine (paper Sec. V-B on the rod of Sec. V, Appendix IV).

Two ways the couple of eq. (19) reaches the rod: :class:`StateFeedback`, the law evaluated on the
rod's own state inside every implicit step (the continuous-time loop of Prop. 5.2, with
``du/dtheta`` in the Newton matrix), and :func:`feedback_at_joints` + :class:`HeldExpansion`, the
sampled law held to first order in the state (what the ROS controller sends). The law reads
eq. (4) at the joints ``s_k = k h``. :func:`rest_shape` is the rod's own static closed loop,
:func:`rest_stability` its linearisation (docs/holding.md, "The cage flutters"). It needs the
rod's geometry only, never the closed-loop runner (:mod:`contgrasp_core.rod.closed_loop` uses
it). docs/rod.md, "Closing the loop".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.contact import shadow_geometry
from contgrasp_core.control.gains import FeedbackGains
from contgrasp_core.control.law import feedback_couple, feedback_couple_and_gradient
from contgrasp_core.errors import IntegrationError, InvalidParameterError
from contgrasp_core.rod import _kernels, chain
from contgrasp_core.rod.model import RodModel

if TYPE_CHECKING:  # (the obstacle imports scipy.spatial: the ROS controller process never needs it)
    from contgrasp_core.rod.integrator import CoupleFeedback
    from contgrasp_core.rod.obstacle import Obstacle

Array = NDArray[np.float64]

__all__ = ["StateFeedback", "joint_couple_jacobian", "FeedbackExpansion", "feedback_at_joints", "HeldExpansion",
           "rest_shape", "RestStability", "rest_stability"]

_SAFE_ONE_PLUS = 0.05  # below this 1 + rho kappa_o the foot's turning rate is dropped from the Jacobian


@dataclass(frozen=True)
class StateFeedback:
    """``u(theta)`` of eq. (19) sensed on the rod itself, with its Jacobian."""

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
        x = chain.nodes(m, theta) if nodes is None else nodes
        geometry = shadow_geometry(x, chain.node_angles(m, theta), self.obstacle)
        rho, alpha = geometry[0][:-1], geometry[1][:-1]
        ei = m.joint_ei
        if not jacobian:
            return feedback_couple(rho, alpha, ei, g.mu1, g.mu2, length_unit=g.length_unit), None
        u, g_rho, g_alpha = feedback_couple_and_gradient(rho, alpha, ei, g.mu1, g.mu2, length_unit=g.length_unit)
        b = chain.frames(theta)[1] if normals is None else normals
        return u, joint_couple_jacobian(m, g_rho, g_alpha, geometry, b)


Geometry = tuple[Array, Array, Array, Array, Array]
"""What :func:`contgrasp_core.contact.shadow_geometry` returns at the rod's N+1 nodes:
``rho``, ``alpha``, ``kappa_o``, ``foot_turn``, ``normal_out``."""


def joint_couple_jacobian(model: RodModel, g_rho: np.ndarray, g_alpha: np.ndarray, geometry: Geometry,
                          b: np.ndarray) -> np.ndarray:
    """``du/dtheta`` (N, N) of a joint couple with partials ``g_rho``, ``g_alpha`` (N,), from the
    rod's shadow geometry at its N+1 nodes (:func:`contgrasp_core.contact.shadow_geometry`, the
    fields of :func:`contgrasp_core.contact.sense` it reads; the joints are nodes 0..N-1).

    Node k moves by ``h b_l`` per unit ``theta_l``, ``l < k``: ``d rho_k / d theta_l = h n_k . b_l``
    (``n_k`` the outward normal ``normal_out`` at the foot) and the foot's tangent angle turns by
    ``h foot_turn_k t_k . b_l`` (``t_k`` the boundary tangent at the foot, ``foot_turn =
    kappa_o / (1 + rho kappa_o)``, eq. (7); taken as 0 where ``1 + rho kappa_o`` is not
    safely positive: there the closest point is degenerate). The node angle is the mean of the
    adjacent elements: ``d alpha_k / d theta_{k-1} = d alpha_k / d theta_k = -1/2``.
    """
    rho, _, kappa_o, foot_turn, normal_out = geometry
    if _kernels.ENABLED:  # the same entries in one compiled loop (contgrasp_core.rod._kernels)
        f64 = _kernels.f64
        return _kernels.joint_couple_jacobian(model.h, f64(g_rho), f64(g_alpha), f64(rho), f64(kappa_o),
                                              f64(foot_turn), f64(normal_out), f64(b), _SAFE_ONE_PLUS)
    n_out = normal_out[:-1]
    safe = 1.0 + rho[:-1] * kappa_o[:-1] > _SAFE_ONE_PLUS
    turn = np.where(safe, foot_turn[:-1], 0.0)
    tangent = np.stack([-n_out[:, 1], n_out[:, 0]], axis=1)
    direction = g_rho[:, None] * n_out + (g_alpha * turn)[:, None] * tangent
    du = model.h * np.tril(direction @ b.T, -1)
    coef = -0.5 * g_alpha
    k = np.arange(1, model.n_elements)
    du[k, k] += coef[1:]
    du[k, k - 1] += coef[1:]
    return du


@dataclass(frozen=True)
class FeedbackExpansion:
    """The feedback law at the N joints, expanded to first order about the sensed state:
    ``u(rho, alpha) ~ u + g_rho (rho - rho_ref) + g_alpha (alpha - alpha_ref)`` (N m, N m/m, N m/rad)."""

    u: Array
    rho_ref: Array
    alpha_ref: Array
    g_rho: Array
    g_alpha: Array


def feedback_at_joints(model: RodModel, gains: FeedbackGains, rho: Array, alpha: Array) -> FeedbackExpansion:
    """Couple of eq. (19) at the N joints from (rho, alpha) sensed at the N+1 nodes,
    with its partial derivatives ``du/drho = -EI sin(alpha) / l^2`` and
    ``du/dalpha = -EI (mu1 sin(alpha) + (rho/l - mu2) cos(alpha)) / l`` (l the law's length unit)."""
    rho, alpha = np.asarray(rho, dtype=float), np.asarray(alpha, dtype=float)
    n = model.n_elements
    if rho.shape != (n + 1,) or alpha.shape != (n + 1,):
        raise InvalidParameterError(f"rho and alpha must be given at the {n + 1} nodes, got {rho.shape}, {alpha.shape}")
    r, a = rho[:-1], alpha[:-1]
    lu, ei = gains.length_unit, model.joint_ei
    u, g_rho, g_alpha = feedback_couple_and_gradient(r, a, ei, gains.mu1, gains.mu2, length_unit=lu)
    return FeedbackExpansion(u=u, rho_ref=r, alpha_ref=a, g_rho=g_rho, g_alpha=g_alpha)


@dataclass(frozen=True)
class HeldExpansion:
    """First-order hold of the feedback law in the STATE (not in time).

    Between samples the integrator adds ``g_rho (rho(theta) - rho_ref) + g_alpha (alpha(theta) -
    alpha_ref)`` to the held couple, with (rho, alpha)(theta) sensed on the rod at the new state
    inside every Newton iteration, and its derivative to the Newton matrix. A plain zero-order
    hold of this law is unstable at any practical control rate (the law acts like a stiffness at
    the element scale, where the tapered tip's bending modes reach ~1000 rad/s; measured: the
    arm crumples at a 1 kHz hold); holding the expansion keeps the continuous law's stability
    while the controller still only runs once per control period.
    """

    model: RodModel
    obstacle: Obstacle
    expansion: FeedbackExpansion

    def couple_and_jacobian(
        self, theta: Array, *, jacobian: bool = True, nodes: Array | None = None, normals: Array | None = None
    ) -> tuple[Array, Array | None]:
        """Deviation of the couple from the held value (N,) and its derivative (N, N)."""
        m, e = self.model, self.expansion
        x = chain.nodes(m, theta) if nodes is None else nodes
        geometry = shadow_geometry(x, chain.node_angles(m, theta), self.obstacle)
        d_alpha = np.mod(geometry[1][:-1] - e.alpha_ref + np.pi, 2.0 * np.pi) - np.pi
        du = e.g_rho * (geometry[0][:-1] - e.rho_ref) + e.g_alpha * d_alpha
        if not jacobian:
            return du, None
        b = chain.frames(theta)[1] if normals is None else normals
        return du, joint_couple_jacobian(m, e.g_rho, e.g_alpha, geometry, b)


def rest_shape(model: RodModel, obstacle: Obstacle, gains: FeedbackGains, *, tol: float = 1e-13,
               max_iterations: int = 50) -> Array:
    """The element angles (N,) of the rod at rest under eq. (19) with no load: the static
    closed loop of the rod itself (eq. (17) at rest with no external force: the total couple
    ``EI_k kappa_k + u_k`` vanishes at every joint, so ``kappa = -u / EI``, eq. (20), joint by
    joint). Swept from the clamp: node ``k``'s position follows from the elements before it,
    its ``rho_k`` and the shadow point's tangent angle from the obstacle's closest point (as the
    rod senses, :func:`contgrasp_core.contact.shadow_geometry`), and ``theta_k`` solves
    ``EI_k (theta_k - theta_(k-1)) / D_k + u_k(rho_k, alpha_k(theta_k)) = 0`` by Newton's method
    (``alpha_k`` through the node angle, the mean of the adjacent elements; at the clamp the
    base angle). The closest point may jump across a concave part of the object, as the rod's
    does: unlike :func:`static_solution`'s ODE the sweep follows it. :class:`IntegrationError`
    if a joint's equation does not converge."""
    n, lu = model.n_elements, gains.length_unit
    ei, d = model.joint_ei, model.joint_len
    mu1 = np.broadcast_to(np.asarray(gains.mu1, dtype=float), (n,))
    mu2 = np.broadcast_to(np.asarray(gains.mu2, dtype=float), (n,))
    theta = np.empty(n)
    x, prev = np.array([model.base_position], dtype=float), float(model.base_angle)
    for k in range(n):
        t = prev
        for _ in range(max_iterations):
            node_angle = prev if k == 0 else 0.5 * (prev + t)
            rho, alpha = shadow_geometry(x, np.array([node_angle]), obstacle)[:2]
            u, _, du_dalpha = feedback_couple_and_gradient(rho, alpha, ei[k], mu1[k], mu2[k], length_unit=lu)
            slope = ei[k] / d[k] - (0.0 if k == 0 else 0.5 * float(du_dalpha[0]))
            step = (ei[k] * (t - prev) / d[k] + float(u[0])) / slope
            t -= step
            if abs(step) <= tol * max(1.0, abs(t)):
                break
        else:
            raise IntegrationError(f"the rod's rest under the feedback law: joint {k} did not converge in "
                                   f"{max_iterations} Newton steps")
        theta[k] = t
        x = x + model.h * np.array([[np.cos(t), np.sin(t)]])
        prev = t
    return theta


@dataclass(frozen=True)
class RestStability:
    """The rod's closed loop linearised about a rest (:func:`rest_stability`): its characteristic
    exponents ``exponents`` (2N,) (1/s; a perturbation grows or decays as ``exp(s t)``)."""

    exponents: NDArray[np.complex128]

    @property
    def growth_rate(self) -> float:
        """The largest real part (1/s): > 0, the rest is unstable."""
        return float(self.exponents.real.max())

    @property
    def frequency(self) -> float:
        """The angular frequency (rad/s) of the fastest-growing mode (0: a real exponent)."""
        return float(abs(self.exponents[np.argmax(self.exponents.real)].imag))


def rest_stability(model: RodModel, feedback: CoupleFeedback, theta: Array) -> RestStability:
    """The closed loop of eq. (17) with the state-feedback couple ``feedback`` (eq. (19)
    sensed on the rod, :class:`StateFeedback`, or the hold (H4),
    :class:`~contgrasp_core.control.hold_law.ShapeHold`)
    linearised about a rest ``theta`` (N,) with no contact:

        M(theta) d'' + zeta M(theta) d' + (K + P du/dtheta) d = 0

    (``M`` the mass matrix, ``zeta`` the rod's mass-proportional damping, ``K`` the bending
    stiffness, ``P`` maps the joint couples' derivative to the generalised forces as the
    integrator does: ``(P X)_j = X_j - X_(j+1)``; the quadratic drag and the centripetal terms
    vanish to first order at rest). Prop. 5.2 asserts asymptotic stability; its proof takes ``u``
    as the gradient of an energy, but ``rho`` and ``alpha`` at ``s`` depend on the whole arm
    before ``s`` (eq. (4)), so ``du/dtheta`` is not symmetric and the loop can flutter (a hold
    (H4) is a potential: ``P du/dtheta`` is symmetric). Undamped by the drag at small amplitude,
    a growth rate above 0 is an oscillation that grows until the drag bounds it."""
    th = np.asarray(theta, dtype=float)
    n = model.n_elements
    if th.shape != (n,) or not np.isfinite(th).all():
        raise InvalidParameterError(f"theta must be {n} finite element angles, got shape {th.shape}")
    _, du = feedback.couple_and_jacobian(th)
    assert du is not None  # (asked for with jacobian=True)
    stiffness = model.stiffness_matrix + du
    stiffness[:-1] -= du[1:]
    mass = chain.mass_matrix(model, th)
    state = np.zeros((2 * n, 2 * n))
    state[:n, n:] = np.eye(n)
    state[n:, :n] = -np.linalg.solve(mass, stiffness)
    state[n:, n:] = -model.damping * np.eye(n)
    return RestStability(np.linalg.eigvals(state).astype(np.complex128))
