"""Rod engine against closed forms (paper eqs. (17) and (18): dynamics, boundary conditions)."""

from __future__ import annotations

import numpy as np
import pytest
from newton_checks import assert_quadratic_convergence, difference_matrix

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import RodLoads, RodModel, RodState, RodSystem, StepOptions
from contgrasp_core.rod import chain

L, R, RHO, E = 1.0, 0.01, 1000.0, 1.0e6
EI = E * np.pi * R**4 / 4
RHO_A = RHO * np.pi * R**2


def uniform(n=40, **kw) -> RodModel:
    return RodModel(length=L, n_elements=n, radius_base=R, radius_tip=R, density=RHO, youngs_modulus=E, **kw)


def relax(system: RodSystem, loads: RodLoads, steps: int = 30, dt: float = 50.0) -> RodState:
    """Backward Euler with huge steps on a damped rod = Newton on the static equilibrium."""
    st = system.straight_state()
    for _ in range(steps):
        st, _ = system.step(st, dt, loads)
    return st


def tip_load(n: int, p: float) -> float:
    m = uniform(n, damping=1.0)
    f = np.zeros((n + 1, 2))
    f[-1, 1] = p
    st = relax(RodSystem(m), RodLoads(node_forces=f))
    return float(chain.nodes(m, st.theta)[-1, 1])


def test_small_tip_load_gives_cantilever_deflection():
    p = 1e-4 * EI / L**2
    assert tip_load(64, p) == pytest.approx(p * L**3 / (3 * EI), rel=2e-3)


def test_element_convergence_is_second_order():
    p = 1e-5 * EI / L**2
    exact = p * L**3 / (3 * EI)
    errs = [abs(tip_load(n, p) - exact) for n in (8, 16, 32)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 1.8) & (orders < 2.2)), orders


def test_uniform_couple_bends_into_circular_arc():
    m = uniform(40, damping=1.0)
    kappa = 2.0
    st = relax(RodSystem(m), RodLoads(couple=np.full(40, -kappa * EI)))
    # eq. (20) statics with a fixed couple: kappa = -u/EI at every joint
    np.testing.assert_allclose(m.joint_curvature(st.theta), kappa, rtol=1e-8)
    x = chain.nodes(m, st.theta)
    # the nodes lie on the circle tangent to the base direction, centre (0, rc), every chord h
    # subtending kappa h (the first element is rotated by kappa h / 2 at the clamp)
    rc = m.h / (2 * np.sin(kappa * m.h / 2))
    d = np.hypot(*(x - np.array([0.0, rc])).T)
    np.testing.assert_allclose(d, rc, rtol=1e-8)
    # and converge to the continuous arc of radius 1/kappa
    tip_exact = np.array([np.sin(kappa * L), 1 - np.cos(kappa * L)]) / kappa
    assert np.hypot(*(x[-1] - tip_exact)) < 0.5 * (m.h * kappa) ** 2 * L


def first_frequency(n: int) -> float:
    lam = 1.8751040687
    return lam**2 * np.sqrt(EI / (RHO_A * L**4)) / (2 * np.pi)


def free_vibration(method: str, dt: float, t_end: float, n: int = 16, amp: float = 0.05):
    """Undamped release from the first linear mode shape (max element angle ``amp``), at rest."""
    from scipy.linalg import eigh

    m = uniform(n)
    sysm = RodSystem(m, options=StepOptions(method=method, tol=1e-12))
    mode = eigh(m.stiffness_matrix, chain.mass_matrix(m, np.zeros(n)))[1][:, 0]
    st = RodState(0.0, amp * mode / np.abs(mode).max(), np.zeros(n))
    e0 = sysm.energy(st)
    ts, ys, es = [0.0], [chain.nodes(m, st.theta)[-1, 1]], [e0]
    for _ in range(int(round(t_end / dt))):
        st, _ = sysm.step(st, dt)
        ts.append(st.t)
        ys.append(chain.nodes(m, st.theta)[-1, 1])
        es.append(sysm.energy(st))
    return np.array(ts), np.array(ys), np.array(es), st


def test_first_natural_frequency_of_uniform_cantilever():
    f1 = first_frequency(16)
    period = 1 / f1
    t, y, _, _ = free_vibration("midpoint", period / 200, 2.2 * period, n=16)
    s = np.sign(y)
    idx = np.flatnonzero(s[1:] != s[:-1])
    tz = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])  # linear interpolation
    measured = 1.0 / np.mean(np.diff(tz[::2]) if len(tz) > 2 else 2 * np.diff(tz))
    assert measured == pytest.approx(f1, rel=0.01)


def test_energy_conservation_orders_without_damping():
    period = 1 / first_frequency(8)
    drift = {}
    for method, ks in (("midpoint", (40, 80)), ("euler", (160, 320))):
        drift[method] = []
        for k in ks:
            _, _, e, _ = free_vibration(method, period / k, period, n=8, amp=0.3)
            drift[method].append(np.abs(e - e[0]).max() / e[0])
    # implicit midpoint: bounded O(dt^2) energy error; backward Euler: O(dt) numerical dissipation
    assert drift["midpoint"][0] < 1e-2
    assert np.log2(drift["midpoint"][0] / drift["midpoint"][1]) == pytest.approx(2.0, abs=0.4)
    assert np.log2(drift["euler"][0] / drift["euler"][1]) == pytest.approx(1.0, abs=0.3)


def test_time_step_convergence_orders():
    # Richardson: successive differences of the state at t = period/2 shrink as dt^order
    period = 1 / first_frequency(8)
    for method, order in (("euler", 1.0), ("midpoint", 2.0)):
        th = [free_vibration(method, period / k, 0.5 * period, n=8, amp=0.02)[3].theta for k in (40, 80, 160)]
        ratio = np.abs(th[0] - th[1]).max() / np.abs(th[1] - th[2]).max()
        assert np.log2(ratio) == pytest.approx(order, abs=0.35), method


def test_energy_decays_monotonically_with_damping_and_drag():
    n = 16
    m = uniform(n, damping=0.5, drag_normal=500.0, drag_tangential=5.0)
    sysm = RodSystem(m)
    st = RodState(0.0, np.linspace(0.0, 1.2, n), np.zeros(n))
    e = [sysm.energy(st)]
    for _ in range(200):
        st, _ = sysm.step(st, 0.05)
        e.append(sysm.energy(st))
    e = np.array(e)
    assert np.all(np.diff(e) <= 1e-12 * e[0])
    assert e[-1] < 0.05 * e[0]


def test_steady_state_under_fixed_couple_profile_is_the_static_shape():
    # tapered rod, couple u(s) = -EI(s) kappa*(s) with kappa*(s) = 3 + 10 s: statics kappa = -u/EI
    m = RodModel(length=0.2, n_elements=80, radius_base=0.01, radius_tip=0.002, density=1042.0,
                 youngs_modulus=1e4, damping=2.0, drag_normal=5110.0, drag_tangential=25.55)
    target = 3.0 + 10.0 * m.joint_s
    sysm = RodSystem(m)
    st = sysm.straight_state()
    for _ in range(400):  # genuine dynamics at dt = 0.05 s until at rest
        st, _ = sysm.step(st, 0.05, RodLoads(couple=-m.joint_ei * target))
    assert np.abs(st.omega).max() < 1e-6
    np.testing.assert_allclose(m.joint_curvature(st.theta), target, rtol=1e-6)
    # continuous static shape: theta(s) = 3 s + 5 s^2, integrated exactly (Gauss) to the nodes
    x = chain.nodes(m, st.theta)
    g, w = np.polynomial.legendre.leggauss(20)
    ss = 0.5 * m.length * (g + 1)
    th = 3 * ss + 5 * ss**2
    tip = 0.5 * m.length * np.array([w @ np.cos(th), w @ np.sin(th)])
    assert np.hypot(*(x[-1] - tip)) < 5e-4


def test_invalid_parameters_raise():
    with pytest.raises(InvalidParameterError):
        RodModel(n_elements=1)
    with pytest.raises(InvalidParameterError):
        RodModel(damping=-1.0)
    with pytest.raises(InvalidParameterError):
        StepOptions(method="rk4")
    with pytest.raises(InvalidParameterError):
        RodSystem(uniform(8)).step(RodSystem(uniform(8)).straight_state(), 0.0)


def _contact_case(method: str, feedback: str):
    """A coarse tapered rod crossing a circle (some centres pressed into it, some moving), with
    damping, drag, friction, a held couple, node forces and optionally the feedback couple."""
    from contgrasp_core.boundary import circle, deformed_circle
    from contgrasp_core.rod import Obstacle
    from contgrasp_core.contact import sense
    from contgrasp_core.rod import chain
    from contgrasp_core.control import paper_gains, StateFeedback
    from contgrasp_core.control import feedback_at_joints, HeldExpansion

    n = 14
    model = RodModel(length=0.2, n_elements=n, radius_base=0.01, radius_tip=0.001, density=1042.0,
                     youngs_modulus=1e4, damping=2.0, drag_normal=5110.0, drag_tangential=25.55,
                     contact_stiffness=1e5, contact_damping=3.0, friction=0.4, friction_velocity=0.01)
    boundary = circle(0.03, (0.1, -0.0347)) if feedback != "deformed" else deformed_circle(0.03, 0.1, 3, 0.2, (0.1, -0.0347))
    system = RodSystem(model, Obstacle(boundary), StepOptions(method=method))
    rng = np.random.default_rng(7)
    state = RodState(t=0.0, theta=0.02 * rng.standard_normal(n), omega=0.5 * rng.standard_normal(n))
    forces = np.zeros((n + 1, 2))
    forces[-1] = (1e-3, -2e-3)
    couple = 1e-5 * rng.standard_normal(n)
    fb = None
    if feedback in ("state", "deformed"):
        fb = StateFeedback(model, system.obstacle, paper_gains(model, 0.03))
    elif feedback == "held":  # the law expanded about a nearby state
        sensed = sense(chain.arm_shape(model, state.theta + 0.01), system.obstacle, model.radius(model.s_nodes))
        fb = HeldExpansion(model, system.obstacle, feedback_at_joints(model, paper_gains(model, 0.03), sensed.rho, sensed.alpha))
    return system, state, RodLoads(couple=couple, node_forces=forces, feedback=fb)


@pytest.mark.parametrize("method", ["euler", "midpoint"])
@pytest.mark.parametrize("feedback", ["none", "state", "held", "deformed"])
def test_newton_matrix_is_the_exact_jacobian_of_the_residual(method: str, feedback: str):
    """Central finite differences of the implicit step's residual reproduce the analytic Newton
    matrix (inertia incl. the mass matrix's angle dependence and the centripetal terms, damping,
    anisotropic drag, penalty contact with damping and friction, node forces, the feedback
    couple): the reason Newton converges quadratically."""
    system, state, loads = _contact_case(method, feedback)
    dt = 2e-3
    frame = system.contact_frame(state, dt)
    assert frame is not None
    rng = np.random.default_rng(3)
    w1 = state.omega + 5.0 * rng.standard_normal(len(state.omega))
    res, jac, ev = system.newton_system(state, w1, dt, loads, frame)
    assert ev.penetration > 0  # contact is active
    fd = difference_matrix(system, state, w1, dt, loads, frame)
    np.testing.assert_allclose(jac, fd, rtol=0, atol=1e-6 * np.abs(jac).max())
    assert np.abs(jac - np.diag(np.diag(jac))).max() > 1e-3 * np.abs(jac).max()  # (not a trivial matrix)


def test_newton_converges_quadratically():
    """With the exact matrix the Newton increments square once they are small: each is at most
    ten times the square of the previous one (rad/s), down to round-off."""
    system, state, loads = _contact_case("euler", "state")
    dt = 2e-3
    assert_quadratic_convergence(system, state, state.omega.copy(), dt, loads, system.contact_frame(state, dt))


def test_a_discontinuous_couple_is_stepped_through_linearly_implicitly():
    """A couple that flips sign across a switching surface (as when a joint's closest point on a
    non-convex object jumps between lobes) leaves the implicit step without a root: Newton
    chatters at any step. After four halvings the integrator takes linearly implicit steps
    instead of failing, and the rod stays at the switching surface (sliding mode)."""
    m = uniform(8, damping=1.0)
    system = RodSystem(m)
    c = 0.2 * EI / L

    class Switching:  # couple -c below the switching angle of the tip element (bends it up), +c above
        def couple_and_jacobian(self, theta, *, jacobian=True, nodes=None, normals=None):  # type: ignore[no-untyped-def]
            u = np.full(len(theta), -c if theta[-1] < 0.03 else c)
            return u, np.zeros((len(theta), len(theta)))

    state, info = system.advance(system.straight_state(), 0.5, RodLoads(feedback=Switching()), dt_try=0.05)
    assert info["linearised_steps"] > 0
    assert np.all(np.isfinite(state.theta)) and abs(state.theta[-1] - 0.03) < 0.01  # (either side alone: +-0.068)
