"""The arm's contact with itself (contgrasp_core.rod.self_contact) against closed forms and identities."""

from __future__ import annotations

import numpy as np
import pytest

from contgrasp_core.rod import RodLoads, RodModel, RodState, RodSystem, chain
from contgrasp_core.rod.self_contact import self_contact_energy, self_contact_frame, self_contact_load, self_gap
from newton_checks import difference_matrix


def _hairpin(overlap: float, radius: float = 2e-3, straight: int = 30, turn: int = 6) -> tuple[RodModel, np.ndarray]:
    """A rod of constant radius: ``straight`` elements along x, a half turn over ``turn`` elements,
    ``straight`` back: two parallel runs whose surfaces overlap by ``overlap`` (m)."""
    n = 2 * straight + turn
    diameter = 2 * radius - overlap  # the runs' centrelines are this far apart
    h = diameter * np.sin(np.pi / (2 * turn))  # the half turn's chords span d
    model = RodModel(length=n * h, n_elements=n, radius_base=radius, radius_tip=radius, damping=0.0,
                     contact_stiffness=1e5, contact_damping=0.0)
    theta = np.concatenate([np.zeros(straight), (np.arange(turn) + 0.5) * np.pi / turn, np.full(straight, np.pi)])
    return model, theta


def test_two_pressed_runs_feel_the_law_once_per_unit_length() -> None:
    overlap = 1e-4
    model, theta = _hairpin(overlap)
    c = chain.centres(model, theta)
    frame = self_contact_frame(model, c, 1e-3)
    assert frame is not None
    load = self_contact_load(model, frame, theta, np.zeros(model.n_elements))
    assert load is not None
    # the centres' chord across the turn is (d/2) 2 sin(...) < d: take the runs' interior, away from both ends
    inner = np.arange(5, 25)
    per_length = load.forces[inner] / model.h
    pen = 2 * model.radius_base - abs(c[inner, 1] - c[-1 - inner, 1])
    assert pen == pytest.approx(np.full(inner.size, overlap), rel=1e-9)
    np.testing.assert_allclose(per_length[:, 1], -model.contact_stiffness * overlap, rtol=1e-9)  # k p, towards -y
    np.testing.assert_allclose(per_length[:, 0], 0.0, atol=1e-12)
    # equal and opposite on the other run; no net force on the arm
    np.testing.assert_allclose(load.forces[-1 - inner], -load.forces[inner], rtol=1e-9)
    np.testing.assert_allclose(load.forces.sum(axis=0), 0.0, atol=1e-12)
    # its generalised force is that of the centre forces
    np.testing.assert_allclose(load.q, chain.generalized_from_centre_forces(model, theta, load.forces), rtol=1e-12, atol=1e-15)
    assert load.overlap == pytest.approx(overlap, rel=1e-6)


def test_a_bend_is_not_a_contact_and_apart_runs_do_not_touch() -> None:
    model, theta = _hairpin(-1e-3)  # 1 mm apart
    assert self_contact_frame(model, chain.centres(model, theta), 2e-4) is None
    assert self_gap(model, theta).gap == pytest.approx(1e-3, rel=1e-9)
    straight = RodModel()
    assert self_gap(straight, np.zeros(straight.n_elements)).gap == np.inf
    # the paper's arm bent to a quarter circle per 5 cm: bends only
    bent = np.cumsum(np.full(straight.n_elements, 0.02))
    assert self_contact_frame(straight, chain.centres(straight, bent), 2e-3) is None


@pytest.mark.parametrize("method", ["euler", "midpoint"])
def test_the_newton_matrix_with_self_contact_is_the_residual_s_derivative(method: str) -> None:
    from contgrasp_core.rod.integrator import StepOptions

    model, theta = _hairpin(2e-4)
    model = RodModel(**{**model.__dict__, "contact_damping": 200.0, "damping": 0.5, "drag_normal": 100.0})
    rng = np.random.default_rng(3)
    state = RodState(t=0.0, theta=theta + 1e-3 * rng.standard_normal(theta.size), omega=3.0 * rng.standard_normal(theta.size))
    system = RodSystem(model, options=StepOptions(method=method))
    dt = 1e-3
    frame = system.self_contact_frame(state, dt)
    assert frame is not None
    w1 = state.omega + 0.1 * rng.standard_normal(theta.size)
    _, jac, ev = system.newton_system(state, w1, dt, RodLoads(), None, frame)
    assert ev.self_overlap > 0
    fd = difference_matrix(system, state, w1, dt, RodLoads(), None, eps=1e-5, self_frame=frame)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6 * np.abs(jac).max())


def test_released_overlapping_runs_spring_apart_without_gaining_energy() -> None:
    model, theta = _hairpin(3e-4)
    system = RodSystem(model)
    state = RodState(t=0.0, theta=theta, omega=np.zeros(theta.size))
    energy = [system.energy(state) + self_contact_energy(model, state.theta)]
    for _ in range(40):
        state, _ = system.step(state, 2e-4)
        energy.append(system.energy(state) + self_contact_energy(model, state.theta))
    e = np.asarray(energy)
    assert e[0] > 0
    assert np.all(np.diff(e) <= 1e-3 * e[0]), np.diff(e).max() / e[0]  # backward Euler: never more than round-off gained
    assert e[-1] < e[0]
    assert self_gap(model, state.theta).gap > -3e-4  # the runs moved apart


def test_the_compiled_search_finds_the_numpy_search_s_pairs(monkeypatch: pytest.MonkeyPatch) -> None:
    from contgrasp_core.rod import _kernels

    model = RodModel()
    rng = np.random.default_rng(11)
    found = 0
    for turns in (2.0, 3.0, 4.0, 6.0):
        theta = np.cumsum(np.full(model.n_elements, 2 * np.pi * turns / model.n_elements)) + 0.05 * rng.standard_normal(model.n_elements)
        c = chain.centres(model, theta)
        frames = []
        for enabled in (True, False):
            monkeypatch.setattr(_kernels, "ENABLED", enabled)
            frames.append(self_contact_frame(model, c, 2e-3))
        compiled, reference = frames
        assert (compiled is None) == (reference is None)
        if compiled is None or reference is None:
            continue
        found += len(compiled.centre)
        np.testing.assert_array_equal(compiled.centre, reference.centre)
        np.testing.assert_array_equal(compiled.segment, reference.segment)
        np.testing.assert_allclose(compiled.t, reference.t, rtol=0, atol=1e-12)
        np.testing.assert_allclose(compiled.normal, reference.normal, rtol=0, atol=1e-12)
    assert found > 20
