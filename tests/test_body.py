"""A movable rigid object in the rod engine (contgrasp_core.rod.body, .coupling): the exact
Newton matrix of the coupled step, closed-form rigid-body motion, the spring's frequency and the
angular momentum balance of rod + object about the clamp."""

from __future__ import annotations

import numpy as np
import pytest
from newton_checks import assert_quadratic_convergence, difference_matrix

from contgrasp_core.boundary import circle, ellipse
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import RodLoads, RodModel, RodState, RodSystem, StepOptions
from contgrasp_core.rod.body import BodyState, ObjectDynamics, RigidBody, mass_properties
from contgrasp_core.rod.obstacle import Obstacle


def _coupled_case(method: str, friction: float = 0.4, spring: bool = True):
    """A coarse tapered rod pressed into a circle that moves and turns, with damping, drag,
    friction, a held couple, node forces and a wrench on the object."""
    n = 14
    model = RodModel(length=0.2, n_elements=n, radius_base=0.01, radius_tip=0.001, density=1042.0,
                     youngs_modulus=1e4, damping=2.0, drag_normal=5110.0, drag_tangential=25.55,
                     contact_stiffness=1e5, contact_damping=3.0, friction=friction, friction_velocity=0.01)
    boundary = ellipse(0.04, 0.03, (0.1, -0.0347), 0.3)
    body = RigidBody(mass=0.05, inertia=2e-5, centroid=(0.1, -0.0347),
                     stiffness=(30.0, 20.0, 0.5) if spring else (0.0, 0.0, 0.0),
                     damping=(0.2, 0.1, 0.01) if spring else (0.0, 0.0, 0.0))
    system = RodSystem(model, Obstacle(boundary), StepOptions(method=method), body=body)
    rng = np.random.default_rng(7)
    state = RodState(t=0.0, theta=0.02 * rng.standard_normal(n), omega=0.5 * rng.standard_normal(n),
                     body=BodyState(q=np.array([2e-4, -1e-3, 0.02]), v=np.array([0.05, -0.03, 0.8])))
    forces = np.zeros((n + 1, 2))
    forces[-1] = (1e-3, -2e-3)
    loads = RodLoads(couple=1e-5 * rng.standard_normal(n), node_forces=forces, wrench=np.array([0.01, -0.02, 1e-4]))
    return system, state, loads


@pytest.mark.parametrize("method", ["euler", "midpoint"])
@pytest.mark.parametrize("spring", [True, False])
def test_coupled_newton_matrix_is_the_exact_jacobian(method: str, spring: bool) -> None:
    """Central differences of the coupled residual (rod rates and object velocity) reproduce the
    analytic matrix, coupling blocks included (contact moving and turning with the object,
    relative-velocity damping and friction, the object's torque, the spring-damper)."""
    system, state, loads = _coupled_case(method, spring=spring)
    dt = 2e-3
    frame = system.contact_frame(state, dt)
    assert frame is not None
    rng = np.random.default_rng(3)
    z = system.rates(state) + np.concatenate([5.0 * rng.standard_normal(14), [0.02, -0.05, 0.7]])
    res, jac, ev = system.newton_system(state, z, dt, loads, frame)
    assert ev.penetration > 0 and jac.shape == (17, 17)
    fd = difference_matrix(system, state, z, dt, loads, frame)
    scale = np.abs(jac).max(axis=1, keepdims=True)  # rows differ in units (rod / object)
    np.testing.assert_allclose(jac / scale, fd / scale, rtol=0, atol=1e-6)
    assert np.abs(jac[:14, 14:]).max() > 0 and np.abs(jac[14:, :14]).max() > 0  # (really coupled)


def test_coupled_newton_converges_quadratically() -> None:
    """With the exact coupled matrix the increments square once they are small, down to round-off."""
    system, state, loads = _coupled_case("euler")
    dt = 2e-3
    assert_quadratic_convergence(system, state, system.rates(state).copy(), dt, loads, system.contact_frame(state, dt))


def _far_object(body: RigidBody) -> RodSystem:
    """A rod that never reaches the object (a circle of radius 2 cm centred 0.5 m away)."""
    model = RodModel(n_elements=10)
    return RodSystem(model, Obstacle(circle(0.02, body.centroid)), StepOptions(method="midpoint"), body=body)


def test_a_free_object_under_a_constant_wrench_moves_as_a_rigid_body() -> None:
    """No contact, a constant wrench: ``x = F t^2 / (2 m)``, ``psi = tau t^2 / (2 J)``, the rod
    untouched (the implicit midpoint rule is exact for constant accelerations)."""
    body = RigidBody(mass=0.03, inertia=4e-6, centroid=(0.5, 0.3))
    system = _far_object(body)
    wrench = np.array([0.02, -0.05, 3e-5])
    state, _ = system.advance(system.straight_state(), 0.1, RodLoads(wrench=wrench), dt_try=0.01)
    assert state.body is not None
    t = state.t
    expected = wrench * t**2 / (2.0 * np.array([body.mass, body.mass, body.inertia]))
    np.testing.assert_allclose(state.body.q, expected, rtol=1e-12, atol=0)
    np.testing.assert_allclose(state.body.v, wrench * t / np.array([body.mass, body.mass, body.inertia]), rtol=1e-12)
    np.testing.assert_array_equal(state.theta, system.straight_state().theta)


def test_a_spring_held_object_oscillates_at_the_analytic_frequency() -> None:
    """Small free oscillation on the spring: each axis ``A cos(sqrt(k/m) t)`` (rotation
    ``sqrt(k_psi / J)``), to the midpoint rule's phase error O((omega dt)^2)."""
    body = RigidBody(mass=0.05, inertia=2e-5, centroid=(0.5, 0.3), stiffness=(30.0, 80.0, 0.01))
    system = _far_object(body)
    q0 = np.array([1e-3, -5e-4, 0.02])
    state = RodState(0.0, system.straight_state().theta, np.zeros(10), BodyState(q=q0, v=np.zeros(3)))
    omega = np.sqrt(np.array(body.stiffness) / body.mass_matrix)
    dt = 2e-4
    worst = 0.0
    for _ in range(1600):
        state, _ = system.step(state, dt)
        assert state.body is not None
        worst = max(worst, float(np.abs((state.body.q - q0 * np.cos(omega * state.t)) / q0).max()))
    assert worst < 2e-3, worst
    assert state.t * omega.min() > 2 * np.pi  # (at least one full period of each axis)


def _angular_momentum(system: RodSystem, state: RodState) -> float:
    """Angular momentum of rod + object about the clamp (kg m^2/s)."""
    from contgrasp_core.rod import chain

    m, body = system.model, system.body
    assert body is not None and state.body is not None
    base = np.asarray(m.base_position)
    c = chain.centres(m, state.theta) - base
    v = chain.centre_velocities(m, state.theta, state.omega)
    rod = np.sum(m.mass * (c[:, 0] * v[:, 1] - c[:, 1] * v[:, 0])) + np.sum(m.rot_inertia * state.omega)
    x = np.asarray(body.centroid) + state.body.q[:2] - base
    vb = state.body.v
    return float(rod + body.mass * (x[0] * vb[1] - x[1] * vb[0]) + body.inertia * vb[2])


@pytest.mark.heavy
def test_rod_and_free_object_balance_angular_momentum_about_the_clamp() -> None:
    """No drag, no damping, no applied loads: the only external moment about the clamp is the
    clamp's couple ``-EI_0 kappa_0``, so the angular momentum of rod + free object changes by
    its time integral while the rod pushes the object away (contact forces, friction included,
    are equal, opposite and collinear)."""
    model = RodModel(n_elements=20, contact_stiffness=2e4, contact_damping=0.5, friction=0.3,
                     friction_velocity=1e-3)
    boundary = circle(0.03, (0.1, 0.036))
    body = ObjectDynamics(mode="free", areal_density=5.0).body(boundary)
    system = RodSystem(model, Obstacle(boundary), StepOptions(method="midpoint"), body=body)
    state = RodState(0.0, np.zeros(20), np.linspace(0.0, 4.0, 20), BodyState.rest())
    dt = 5e-5
    start = _angular_momentum(system, state)
    impulse = 0.0
    for _ in range(1500):
        new, _ = system.step(state, dt)
        mid = 0.5 * (state.theta + new.theta)
        impulse -= dt * model.joint_ei[0] * (mid[0] - model.base_angle) / model.joint_len[0]
        state = new
    assert state.body is not None
    transferred = body.mass * np.hypot(*state.body.v[:2]) * 0.1  # the object's share, for scale
    assert transferred > 1e-6  # (the rod did push the object)
    assert abs(_angular_momentum(system, state) - start - impulse) < 1e-6 * transferred


def test_mass_properties_of_circle_and_ellipse() -> None:
    """Area, centroid and polar moment against the closed forms ``pi R^2``, ``pi R^4 / 2`` and
    ``pi a b``, ``pi a b (a^2 + b^2) / 4``."""
    area, c, jz = mass_properties(circle(0.03, (0.1, -0.2)))
    np.testing.assert_allclose([area, jz], [np.pi * 0.03**2, np.pi * 0.03**4 / 2], rtol=1e-6)
    np.testing.assert_allclose(c, [0.1, -0.2], atol=1e-12)
    a, b = 0.04, 0.025
    area, c, jz = mass_properties(ellipse(a, b, (0.3, 0.1), 0.7))
    np.testing.assert_allclose([area, jz], [np.pi * a * b, np.pi * a * b * (a**2 + b**2) / 4], rtol=1e-5)
    np.testing.assert_allclose(c, [0.3, 0.1], atol=1e-9)


def test_fixed_is_no_body_and_bad_input_is_a_clear_error() -> None:
    assert ObjectDynamics().body(circle(0.03)) is None
    with pytest.raises(InvalidParameterError, match="mass"):
        ObjectDynamics(mode="free", mass=-1.0)
    with pytest.raises(InvalidParameterError, match="stiffness"):
        ObjectDynamics(mode="spring", stiffness=(1.0, 2.0))
    with pytest.raises(InvalidParameterError, match="mode"):
        ObjectDynamics(mode="floating")
    body = RigidBody(mass=0.03, inertia=4e-6, centroid=(0.5, 0.3))
    system = _far_object(body)
    with pytest.raises(InvalidParameterError, match="wrench"):
        system.advance(system.straight_state(), 0.01, RodLoads(wrench=np.array([np.nan, 0.0, 0.0])))
    with pytest.raises(InvalidParameterError, match="wrench"):
        RodSystem(RodModel(n_elements=4)).advance(RodSystem(RodModel(n_elements=4)).straight_state(), 0.01,
                                                   RodLoads(wrench=np.zeros(3)))


def test_sensing_follows_the_moved_object() -> None:
    """Two computations of the contact state against a displaced, turned ellipse agree: the arm
    sensed against the moved obstacle (points taken into the object frame and back), and the arm
    moved into the object's frame sensed against the start-pose boundary (what the sampled loop
    does, ``session.sensed_shape``): rho, alpha and the foot's turning rate are invariant."""
    from contgrasp_core.contact import sense
    from contgrasp_core.rod import chain
    from contgrasp_core.rod.body import rotation, shape_in_object_frame, to_world

    boundary = ellipse(0.04, 0.03, (0.1, -0.0347), 0.3)
    model = RodModel(n_elements=40)
    theta = np.linspace(0.0, 1.5, 40)
    shape = chain.arm_shape(model, theta)
    q, centroid = np.array([0.004, 0.012, 0.4]), np.array([0.1, -0.0347])
    radius = model.radius(model.s_nodes)
    moved = sense(shape, Obstacle(boundary).moved(q, centroid), radius)
    in_frame = sense(shape_in_object_frame(shape, q, centroid), boundary, radius)
    np.testing.assert_allclose(moved.rho, in_frame.rho, rtol=0, atol=1e-9)
    np.testing.assert_allclose(moved.alpha, in_frame.alpha, rtol=0, atol=1e-7)
    # the same table projection in the object's frame: the foot and normal moved with the object
    fixed = sense(shape_in_object_frame(shape, q, centroid), Obstacle(boundary), radius)
    np.testing.assert_allclose(moved.foot_turn, fixed.foot_turn, rtol=1e-12)
    np.testing.assert_allclose(moved.foot, to_world(fixed.foot, q, centroid), atol=1e-12)
    np.testing.assert_allclose(moved.normal_out, fixed.normal_out @ rotation(q[2]).T, atol=1e-12)
    assert np.abs(moved.rho - sense(shape, Obstacle(boundary), radius).rho).max() > 1e-3  # (it did move)


@pytest.mark.heavy
def test_the_sampled_loop_pushes_a_free_object_and_holds_a_spring_held_one() -> None:
    """The paper's sampled loop (N = 40 for speed) with the object free, on a spring and fixed:
    the free object is pushed away by the wrapping arm, the spring-held one moves less, the
    fixed one not at all and gives exactly the fixed-object engine's result."""
    from dataclasses import replace

    from contgrasp_core.rod.session import run_sampled
    from contgrasp_core.scenario import PAPER

    base = replace(PAPER, rod=replace(PAPER.rod, n_elements=40), loop=replace(PAPER.loop, duration=1.2))
    moved = {}
    for dyn in (ObjectDynamics("free"), ObjectDynamics("spring", stiffness=(200.0, 200.0, 0.2), damping=(2.0, 2.0, 0.002))):
        s = run_sampled(replace(base, dynamics=dyn))
        assert s.state.body is not None and s.max_penetration < 1e-3
        moved[dyn.mode] = float(np.hypot(*s.state.body.q[:2]))
    assert moved["free"] > 2.0 * moved["spring"] > 0.0, moved
    fixed = run_sampled(base)
    reference = run_sampled(base, RodSystem(base.rod, Obstacle(base.object.boundary())))
    assert fixed.state.body is None
    np.testing.assert_array_equal(fixed.state.theta, reference.state.theta)


@pytest.mark.heavy
def test_simulate_object_mode_reports_the_object_and_rejects_bad_input() -> None:
    """``contgrasp simulate --object-mode`` runs the continuous loop with the object moving and
    reports its motion; a negative mass, a spring of the wrong shape or a NaN is exit 2."""
    import json
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "contgrasp_core.cli", "simulate", "--nodes", "21", "--duration", "1.2", "--json"]
    fixed = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)
    free = json.loads(subprocess.run(cmd + ["--object-mode", "free"], capture_output=True, text=True, check=True).stdout)
    assert fixed["object_mode"] == "fixed" and fixed["object_displacement"] is None and fixed["object_velocity"] is None
    assert free["object_mode"] == "free" and np.hypot(free["object_displacement"]["x"], free["object_displacement"]["y"]) > 1e-5
    for bad in (["--object-mode", "free", "--object-mass", "-1"], ["--object-mode", "spring", "--object-stiffness", "1", "2"],
                ["--object-mode", "spring", "--object-damping", "1", "nan", "1"], ["--object-stiffness", "1", "1", "1"],
                ["--object-mass", "1"], ["--object-inertia", "1"], ["--object-density", "5"]):  # (the fixed object: no inertia)
        p = subprocess.run(cmd + bad, capture_output=True, text=True)
        assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, (bad, p.stderr)


def test_disturbance_profiles_and_validation() -> None:
    from contgrasp_core.rod.disturbance import Disturbance

    w = (0.2, -0.1, 0.003)
    step, ramp, pulse = Disturbance("step", w, 1.0), Disturbance("ramp", w, 1.0, 0.5), Disturbance("pulse", w, 1.0, 0.25)
    for d in (step, ramp, pulse):
        np.testing.assert_array_equal(d.wrench_at(0.999), np.zeros(3))
    np.testing.assert_array_equal(step.wrench_at(1.0), w)
    np.testing.assert_allclose(ramp.wrench_at(1.25), 0.5 * np.array(w))
    np.testing.assert_array_equal(ramp.wrench_at(3.0), w)
    np.testing.assert_array_equal(pulse.wrench_at(1.2), w)
    np.testing.assert_array_equal(pulse.wrench_at(1.25), np.zeros(3))
    for bad in (dict(kind="kick", wrench=w), dict(kind="step", wrench=(1.0, np.nan, 0.0)), dict(kind="step", wrench=(1.0, 2.0)),
                dict(kind="pulse", wrench=w, duration=0.0), dict(kind="step", wrench=w, start=-1.0)):
        with pytest.raises(InvalidParameterError, match="disturbance|duration"):
            Disturbance(**bad)  # type: ignore[arg-type]
    from contgrasp_core.scenario import PAPER
    from dataclasses import replace
    with pytest.raises(InvalidParameterError, match="movable"):
        replace(PAPER, disturbance=step)


@pytest.mark.parametrize("movable", [True, False])
@pytest.mark.parametrize("method", ["euler", "midpoint"])
def test_stick_slip_newton_matrix_is_exact(movable: bool, method: str) -> None:
    """The stick-slip tangential force (an elastic spring to the anchor inside the Coulomb cone,
    Coulomb's force at its edge) has the exact derivative in the Newton matrix, against a
    moving object and a fixed one; the case has both sticking and slipping contacts."""
    from dataclasses import replace

    system, state, loads = _coupled_case(method)
    model = replace(system.model, friction_model="stick", friction=0.3)
    if movable:
        system = replace(system, model=model)
    else:
        system = RodSystem(model, system.obstacle, system.options)
        state = replace(state, body=None)
        loads = replace(loads, wrench=None)
    state = replace(state, omega=np.zeros_like(state.omega),
                    body=None if state.body is None else replace(state.body, v=np.zeros(3)))
    dt = 2e-3
    rng = np.random.default_rng(5)
    frame = system.contact_frame(state, dt)
    assert frame is not None and frame.anchors is not None
    # anchors spread around the contacts so that some stick and some slip
    anchors = frame.anchors.copy()
    spread = np.where(np.arange(len(frame.rows)) % 2 == 0, 1e-7, 5e-3)[:, None]
    anchors[frame.rows] += spread * rng.standard_normal((len(frame.rows), 2))
    frame = replace(frame, anchors=anchors)
    z = system.rates(state) + 0.01 * rng.standard_normal(len(system.rates(state)))
    res, jac, ev = system.newton_system(state, z, dt, loads, frame)
    assert ev.anchors is not None
    moved = ~np.isnan(ev.anchors[:, 0]) & ~np.isclose(ev.anchors, anchors).all(axis=1)
    kept = ~np.isnan(ev.anchors[:, 0]) & np.isclose(ev.anchors, anchors).all(axis=1)
    assert moved.any() and kept.any()  # (slipping and sticking contacts)
    fd = difference_matrix(system, state, z, dt, loads, frame, eps=1e-7)
    scale = np.abs(jac).max(axis=1, keepdims=True)
    np.testing.assert_allclose(jac / scale, fd / scale, rtol=0, atol=1e-5)
