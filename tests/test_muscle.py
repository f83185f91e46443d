"""Muscles with limits (contgrasp_core.rod.muscle): the bound's geometry, the saturated rest shape
and the saturation inside the implicit step."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import integrate

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import RodLoads, RodModel, RodSystem
from contgrasp_core.rod.muscle import saturate
from newton_checks import difference_matrix


def test_the_bound_is_the_half_section_pulling_at_the_largest_stress() -> None:
    model = RodModel(max_muscle_stress=2e4)
    assert model.muscle_bound is not None and RodModel().muscle_bound is None
    for k in (0, 37, 99):  # the first moment of the half disc of the joint's radius, integrated in polar coordinates
        r = float(model.radius(model.joint_s[k]))
        moment, _ = integrate.dblquad(lambda rho, phi: rho * np.sin(phi) * rho, 0.0, np.pi, 0.0, r)
        assert model.muscle_bound[k] == pytest.approx(2e4 * moment, rel=1e-10)
    with pytest.raises(InvalidParameterError, match="max_muscle_stress"):
        RodModel(max_muscle_stress=-1.0)


def test_a_couple_beyond_the_muscles_bends_the_arm_to_the_bound_over_ei() -> None:
    """Free of loads the arm rests where EI kappa + u = 0 at every joint: with the couple asked
    for beyond the bound, kappa = -bound / EI (the closed form of the saturated rest)."""
    model = RodModel(n_elements=20, damping=3.0, max_muscle_stress=1e3)
    assert model.muscle_bound is not None
    asked = 3.0 * model.muscle_bound  # everywhere beyond what the muscles make
    system = RodSystem(model)
    state = system.straight_state()
    for _ in range(60):
        state, _ = system.advance(state, 1.0, RodLoads(couple=asked))
    kappa = model.joint_curvature(state.theta)
    np.testing.assert_allclose(kappa, -model.muscle_bound / model.joint_ei, rtol=1e-6)
    unbounded = RodSystem(replace(model, max_muscle_stress=0.0))
    free = unbounded.straight_state()
    for _ in range(60):
        free, _ = unbounded.advance(free, 1.0, RodLoads(couple=model.muscle_bound * 0.5))
    np.testing.assert_allclose(model.joint_curvature(free.theta), -0.5 * model.muscle_bound / model.joint_ei, rtol=1e-6)


def test_saturate_clips_each_joint_to_its_bound() -> None:
    model = RodModel(n_elements=4, max_muscle_stress=1e4)
    b = model.muscle_bound
    assert b is not None
    u = np.array([2.0, -2.0, 0.5, -0.25]) * b
    np.testing.assert_array_equal(saturate(model, u), np.array([1.0, -1.0, 0.5, -0.25]) * b)
    plain = RodModel(n_elements=4)
    assert saturate(plain, u) is u


@pytest.mark.parametrize("method", ["euler", "midpoint"])
def test_the_newton_matrix_of_a_saturated_state_feedback_is_exact(method: str) -> None:
    """The law's couple saturates at some joints and not at others; the Newton matrix (with the
    saturation's Jacobian) equals central differences of the residual."""
    from test_rod_physics import _contact_case

    system, state, loads = _contact_case(method, "state")
    u = loads.feedback.couple_and_jacobian(state.theta, jacobian=False)[0] + loads.couple
    model = system.model
    sigma = 0.5 * np.median(np.abs(u) / (2.0 / 3.0 * model.radius(model.joint_s) ** 3))
    system = replace(system, model=replace(model, max_muscle_stress=float(sigma)))
    loads = replace(loads, feedback=replace(loads.feedback, model=system.model))
    bound = system.model.muscle_bound
    assert bound is not None and 0 < np.sum(np.abs(u) > bound) < len(u)  # some joints saturate, not all
    dt = 2e-3
    frame = system.contact_frame(state, dt)
    rng = np.random.default_rng(3)
    w1 = state.omega + 1e-3 * rng.standard_normal(len(state.omega))
    _, jac, _ = system.newton_system(state, w1, dt, loads, frame)
    fd = difference_matrix(system, state, w1, dt, loads, frame)
    np.testing.assert_allclose(jac, fd, rtol=0, atol=1e-6 * np.abs(jac).max())
    unsaturated = replace(system, model=model)
    _, plain, _ = unsaturated.newton_system(state, w1, dt, replace(loads, feedback=replace(loads.feedback, model=model)), frame)
    assert np.abs(plain - jac).max() > 1e-3 * np.abs(jac).max()  # the saturation changed the matrix


def test_a_stiff_held_shape_saturating_part_way_converges_without_halving_to_the_saturated_rest() -> None:
    """A held shape (H4) of stiffness G = 3000 asks for twice the curvature the muscles can hold
    over the base half and half of it over the tip half (the muscles scaled so the rest turns the
    arm by 2/3 rad). Inside the implicit step its couple saturates part-way: at the kink the Newton
    matrix's rows drop 3000-fold, and a full Newton step across it cycles (the step was halved
    to 0.1 ms and below). With the backtracking of bounded muscles each 10 ms step converges in a
    few iterations, and the arm rests at the closed form: EI kappa + u = 0 with u saturated, so
    kappa = clip(kappa_ref, +-bound / EI)."""
    from contgrasp_core.control.hold_law import ShapeHold
    from contgrasp_core.scenario import PAPER

    model = replace(PAPER.rod, n_elements=20, max_muscle_stress=1e4)
    model = replace(model, max_muscle_stress=1e4 / float(np.sum(model.muscle_bound / model.joint_ei * model.joint_len)))
    limit = model.muscle_bound / model.joint_ei  # the largest curvature the muscles hold, 1/m
    kappa_ref = np.where(np.arange(20) < 10, 2.0, 0.5) * limit
    hold = ShapeHold(model, kappa_ref, 3000.0)
    system = RodSystem(model)
    state, substeps, iterations = system.straight_state(), 0, 0
    for _ in range(1500):
        state, info = system.step(state, 0.01, RodLoads(couple=hold.couple, feedback=hold))
        substeps, iterations = substeps + info["substeps"], iterations + info["iterations"]
    np.testing.assert_allclose(model.joint_curvature(state.theta), np.clip(kappa_ref, -limit, limit), rtol=1e-4)
    assert substeps <= 1.2 * 1500 and iterations <= 5 * 1500, (substeps, iterations)
