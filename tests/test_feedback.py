"""Feedback law, units, Prop. 5.1 equilibrium and Lyapunov function (paper Sec. V-B, App. II, IV)."""

from __future__ import annotations

import numpy as np
import pytest

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.control.law import (
    CENTIMETRE,
    adaptive_mu2,
    closed_loop_kinematics,
    curvature_feedback,
    equilibrium_distance,
    feedback_couple,
    feedback_couple_and_gradient,
    feedback_couple_gradient,
    lyapunov,
    lyapunov_rate,
)


def test_curvature_feedback_in_centimetres_by_hand():
    # rho = 5 cm, alpha = 60 deg, mu1 = 1, mu2 = 0.5 cm: kappa = -0.5 + 4.5 sin 60 (1/cm)
    k = curvature_feedback(0.05, np.pi / 3, 1.0, 0.5)
    assert k == pytest.approx((-0.5 + 4.5 * np.sin(np.pi / 3)) * 100.0, rel=1e-12)
    # the same law evaluated in metres is a different curvature (the law is not homogeneous)
    k_m = curvature_feedback(0.05, np.pi / 3, 1.0, 0.005, length_unit=1.0)
    assert k_m == pytest.approx(-0.5 + 0.045 * np.sin(np.pi / 3), rel=1e-12)


def test_feedback_couple_is_minus_ei_times_static_curvature():
    rho = np.array([0.01, 0.02, 0.03])
    alpha = np.array([0.3, 1.5, 2.0])
    ei = np.array([1e-5, 2e-5, 3e-5])
    mu2 = np.array([0.2, -0.1, 0.4])
    u = feedback_couple(rho, alpha, ei, 1.3, mu2)
    # eq. (20): static kappa = -u / EI
    np.testing.assert_allclose(-u / ei, curvature_feedback(rho, alpha, 1.3, mu2), rtol=1e-14)
    with pytest.raises(InvalidParameterError):
        feedback_couple(rho, alpha, -ei, 1.0, 0.0)


@pytest.mark.parametrize("r_arm", [0.001, 0.0035, 0.01])
def test_adaptive_mu2_places_equilibrium_at_the_arm_radius(r_arm):
    # Appendix IV: mu2(s) = r - 1/(r_obj + r) makes rho_d = r(s) the Prop. 5.1 root (cm units)
    r_obj = 0.025
    mu2 = float(adaptive_mu2(r_arm, r_obj))
    rho_d = equilibrium_distance(1.0 / r_obj, mu2, length_unit=CENTIMETRE)
    assert rho_d == pytest.approx(r_arm, rel=1e-12)


@pytest.mark.parametrize("kbar,mu2", [(0.0, 0.7), (0.2, 1.0), (1.0, -0.5), (3.0, 0.0), (0.5, 4.0)])
def test_equilibrium_distance_is_the_positive_root(kbar, mu2):
    rho = equilibrium_distance(kbar, mu2)
    assert rho > 0
    # eq. (21) (the quadratic of Prop. 5.1) and eq.
    assert kbar * rho**2 + (1 - mu2 * kbar) * rho - (mu2 + kbar) == pytest.approx(0.0, abs=1e-12)
    assert -(rho - mu2) + kbar / (1 + rho * kbar) == pytest.approx(0.0, abs=1e-12)
    roots = np.roots([kbar, 1 - mu2 * kbar, -(mu2 + kbar)]) if kbar > 0 else np.array([mu2])
    assert np.sum(roots.real > 0) == 1


@pytest.mark.parametrize("kbar,mu2", [(-0.1, 1.0), (0.5, -0.5), (0.5, -2.0), (0.0, 0.0)])
def test_equilibrium_distance_rejects_outside_prop1(kbar, mu2):
    with pytest.raises(InvalidParameterError):
        equilibrium_distance(kbar, mu2)


CASES = [  # kbar, mu1, mu2, rho0, alpha0
    (0.0, 1.0, 1.0, 2.0, 1.2),
    (0.2, 1.0, 0.5, 3.0, 2.0),
    (0.5, 2.0, -0.3, 1.0, 0.9),
    (1.0, 0.5, 0.2, 0.5, 1.8),
]


@pytest.mark.parametrize("kbar,mu1,mu2,rho0,alpha0", CASES)
def test_prop1_closed_loop_converges_and_lyapunov_decreases(kbar, mu1, mu2, rho0, alpha0):
    s = np.linspace(0.0, 40.0, 4001)
    sol = closed_loop_kinematics(rho0, alpha0, s, mu1, mu2, kbar, length_unit=1.0)
    rho_d = equilibrium_distance(kbar, mu2)
    assert sol.rho[-1] == pytest.approx(rho_d, abs=1e-4)
    assert sol.alpha[-1] == pytest.approx(np.pi / 2, abs=1e-4)
    v = lyapunov(sol.rho, sol.alpha, mu2, kbar)
    assert np.all(np.diff(v) <= 1e-10)
    # dV/ds along the solution equals -mu1 cos^2(alpha)/sin(alpha)
    dv = np.gradient(v, s, edge_order=2)
    np.testing.assert_allclose(dv[5:-5], lyapunov_rate(sol.alpha, mu1)[5:-5], atol=2e-4 * (1 + np.abs(dv[5:-5]).max()))
    # the shadow point moves forward (nu_o > 0) and the static curvature is the feedback law
    assert np.all(np.diff(sol.s_o) > 0)
    np.testing.assert_allclose(sol.kappa, -mu1 * np.cos(sol.alpha) + (sol.rho - mu2) * np.sin(sol.alpha), rtol=1e-12)


def test_lyapunov_gradient_matches_analytic_rate_pointwise():
    # dV/ds = dV/drho * (-cos a) + dV/dalpha * (-kappa + kbar sin a / (1 + rho kbar))
    rng = np.random.default_rng(1)
    kbar, mu1, mu2 = 0.4, 1.5, 0.3
    for _ in range(20):
        rho, a = rng.uniform(0.2, 3.0), rng.uniform(0.2, 2.9)
        e = 1e-6
        dvr = (lyapunov(rho + e, a, mu2, kbar) - lyapunov(rho - e, a, mu2, kbar)) / (2 * e)
        dva = (lyapunov(rho, a + e, mu2, kbar) - lyapunov(rho, a - e, mu2, kbar)) / (2 * e)
        kap = -mu1 * np.cos(a) + (rho - mu2) * np.sin(a)
        rate = dvr * (-np.cos(a)) + dva * (-kap + kbar * np.sin(a) / (1 + rho * kbar))
        assert rate == pytest.approx(float(lyapunov_rate(a, mu1)), rel=1e-6, abs=1e-8)


def test_closed_loop_kinematics_with_arclength_varying_gain_in_cm():
    # paper scenario kinematics: tapered arm, adaptive mu2(s). rho tracks rho_d = r(s) with a small
    # lag and alpha settles slightly below pi/2 because of the taper (paper Sec. V-C).
    L, r0, r1, R = 0.2, 0.01, 0.001, 0.025
    s = np.linspace(0.0, L, 801)

    def mu2(si):
        return adaptive_mu2(r0 + (r1 - r0) * si / L, R)

    sol = closed_loop_kinematics(0.02, np.pi / 2, s, 1.0, mu2, 1.0 / R)
    r = r0 + (r1 - r0) * s / L
    tail = s > 0.08
    assert np.max(np.abs(sol.rho[tail] - r[tail])) < 0.8e-3
    assert np.all(sol.alpha[tail] < np.pi / 2)
    assert np.all(sol.alpha[tail] > np.pi / 2 - 0.1)


def test_validation_of_inputs():
    with pytest.raises(InvalidParameterError):
        curvature_feedback(0.01, 1.0, 1.0, 0.0, length_unit=0.0)
    with pytest.raises(InvalidParameterError):
        adaptive_mu2(-0.01, 0.025)
    with pytest.raises(InvalidParameterError):
        closed_loop_kinematics(-1.0, 1.0, np.linspace(0, 1, 5), 1.0, 1.0, 0.0)
    with pytest.raises(InvalidParameterError):
        closed_loop_kinematics(1.0, 1.0, np.array([0.0, 0.0, 1.0]), 1.0, 1.0, 0.0)


@pytest.mark.parametrize("mu2", [1.3, np.linspace(-0.4, 2.0, 30)], ids=["scalar", "per-joint"])
def test_feedback_couple_and_gradient_are_the_two_functions_bit_for_bit(mu2) -> None:  # type: ignore[no-untyped-def]
    """The controller's one-pass law returns exactly feedback_couple and feedback_couple_gradient;
    bad inputs are rejected the same way."""
    rng = np.random.default_rng(3)
    rho, alpha, ei = rng.uniform(-0.01, 0.08, 30), rng.uniform(-3.0, 3.0, 30), rng.uniform(1e-4, 1e-2, 30)
    u, g_rho, g_alpha = feedback_couple_and_gradient(rho, alpha, ei, 0.7, mu2, length_unit=CENTIMETRE)
    np.testing.assert_array_equal(u, feedback_couple(rho, alpha, ei, 0.7, mu2, length_unit=CENTIMETRE))
    want = feedback_couple_gradient(rho, alpha, ei, 0.7, mu2, length_unit=CENTIMETRE)
    np.testing.assert_array_equal(g_rho, want[0])
    np.testing.assert_array_equal(g_alpha, want[1])
    with pytest.raises(InvalidParameterError, match="not finite"):
        feedback_couple_and_gradient(np.full(30, np.nan), alpha, ei, 0.7, mu2)
    with pytest.raises(InvalidParameterError, match="bending_stiffness"):
        feedback_couple_and_gradient(rho, alpha, -ei, 0.7, mu2)


def test_feedback_expansion_gains_are_the_law_derivatives() -> None:
    """du/drho and du/dalpha of the controller's expansion against central differences."""
    from contgrasp_core.control import paper_gains
    from dataclasses import replace

    from contgrasp_core.scenario import PAPER
    from contgrasp_core.control import feedback_at_joints

    model = replace(PAPER.rod, n_elements=20)
    gains = paper_gains(model, 0.025)
    rng = np.random.default_rng(0)
    rho = rng.uniform(0.001, 0.08, 21)
    alpha = rng.uniform(0.2, 2.9, 21)
    e = feedback_at_joints(model, gains, rho, alpha)
    h_r, h_a = 1e-7, 1e-6
    d_rho = (feedback_at_joints(model, gains, rho + h_r, alpha).u - feedback_at_joints(model, gains, rho - h_r, alpha).u) / (2 * h_r)
    d_alpha = (feedback_at_joints(model, gains, rho, alpha + h_a).u - feedback_at_joints(model, gains, rho, alpha - h_a).u) / (2 * h_a)
    np.testing.assert_allclose(e.g_rho, d_rho, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(e.g_alpha, d_alpha, rtol=1e-6, atol=1e-14)
