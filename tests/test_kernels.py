"""The compiled kernels (contgrasp_core.rod._kernels) against the numpy code they replace: equal to
rounding, term by term and over a closed-loop run; the circle's closed-form projection against
the general closest-point search."""

from __future__ import annotations

import numpy as np
import pytest

from contgrasp_core.arm import ArmShape
from contgrasp_core.boundary import circle, ellipse
from contgrasp_core.control import feedback_at_joints
from contgrasp_core.contact import sense, shadow_geometry
from contgrasp_core.control.rod_feedback import joint_couple_jacobian
from contgrasp_core.rod import Obstacle, RodSystem, _kernels
from contgrasp_core.rod import chain
from contgrasp_core.rod.session import LoopSession
from contgrasp_core.scenario import PAPER
from test_rod_physics import _contact_case


def _both(fn):  # type: ignore[no-untyped-def]
    before = _kernels.ENABLED
    try:
        _kernels.ENABLED = False
        ref = fn()
        _kernels.ENABLED = True
        got = fn()
    finally:
        _kernels.ENABLED = before
    return ref, got


@pytest.mark.parametrize("method", ["euler", "midpoint"])
@pytest.mark.parametrize("feedback", ["none", "state", "held", "deformed"])
def test_newton_system_kernel_equals_numpy_to_rounding(method: str, feedback: str) -> None:
    """Residual, Newton matrix and penetration of the kernel and of RodSystem._evaluate, with
    contact (damping and friction), drag, node forces, held couple and every feedback."""
    system, state, loads = _contact_case(method, feedback)
    dt = 2e-3
    frame = system.contact_frame(state, dt)
    rng = np.random.default_rng(5)
    w1 = state.omega + 5.0 * rng.standard_normal(len(state.omega))
    (r0, j0, e0), (r1, j1, e1) = _both(lambda: system.newton_system(state, w1, dt, loads, frame))
    assert np.abs(r1 - r0).max() <= 1e-13 * np.abs(r0).max()
    assert np.abs(j1 - j0).max() <= 1e-13 * np.abs(j0).max()
    assert e1.penetration == pytest.approx(e0.penetration, rel=1e-13)
    # and without contact or feedback (the kernel's empty-array branches)
    (r0, j0, _), (r1, j1, _) = _both(lambda: system.newton_system(state, w1, dt))
    assert np.abs(r1 - r0).max() <= 1e-13 * np.abs(r0).max()
    assert np.abs(j1 - j0).max() <= 1e-13 * np.abs(j0).max()


def test_joint_couple_jacobian_kernel() -> None:
    model = PAPER.rod
    obstacle = Obstacle(PAPER.object.boundary())
    theta = np.linspace(0.0, 2.5, model.n_elements)
    js = shadow_geometry(chain.nodes(model, theta), chain.node_angles(model, theta), obstacle)
    rng = np.random.default_rng(2)
    g_rho, g_alpha = rng.standard_normal((2, model.n_elements))
    b = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    ref, got = _both(lambda: joint_couple_jacobian(model, g_rho, g_alpha, js, b))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-15 * np.abs(ref).max())


def test_obstacle_circle_kernel() -> None:
    obstacle = Obstacle(circle(0.025, (0.08, 0.08)))
    q = 0.08 + 0.05 * np.random.default_rng(4).standard_normal((500, 2))
    q[0] = (0.08, 0.08)  # the centre: normal (1, 0) by convention
    ref, got = _both(lambda: obstacle.project(q))
    for name in ("foot", "s_o", "phi", "kappa_o", "signed_distance", "normal_out"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=0, atol=1e-15, err_msg=name)


def test_circle_sensing_kernel_equals_numpy_to_rounding() -> None:
    """sense() against a circle Boundary, compiled in one pass, against the numpy path: every
    field to rounding, the seam (s_o unwrapped along an arm that winds round the circle more than
    once, backwards too), a point at the centre and points on the circle itself (rho = 0, where
    1 + rho kappa_o and the signs meet their edge cases) included."""
    rng = np.random.default_rng(11)
    for trial in range(200):
        n = int(rng.integers(1, 80))
        b = circle(float(rng.uniform(0.01, 1.0)), (float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1))))
        R, c = b.params["R"], np.asarray(b.params["center"])
        turns = np.cumsum(rng.uniform(-0.3, 1.2, n))  # (winds round up to ~10 times, with steps back)
        dist = rng.uniform(0.0, 2.0, n) * R
        if trial % 4 == 0:
            dist[rng.integers(0, n)] = R  # on the circle
        q = c + dist[:, None] * np.stack([np.cos(turns), np.sin(turns)], -1)
        if trial % 5 == 0:
            q[0] = c  # the centre
        shape = ArmShape(s=0.01 * np.arange(n), r=q, theta=rng.uniform(-7.0, 7.0, n))
        radius = rng.uniform(0.0, 0.02, n)
        ref, got = _both(lambda: sense(shape, b, radius, tol=1e-3))  # noqa: B023 (called at once)
        for name in ("rho", "alpha", "delta", "s_o", "foot", "kappa_o", "nu_o", "foot_turn", "normal_out"):
            np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-13, atol=2e-15 * max(1.0, R * turns.max()),
                                       err_msg=name)
        for name in ("in_contact", "valid"):  # (edge cases aside: one flag may flip at a tie)
            assert np.sum(getattr(got, name) != getattr(ref, name)) <= (1 if trial % 4 == 0 else 0), name


def _same_projection(fast, slow, length: float, scale: float) -> None:  # type: ignore[no-untyped-def]
    """Equal to the general search's own accuracy (its Newton stops at a parameter step of 1e-13)."""
    np.testing.assert_array_equal(fast.side, slow.side)
    for name, tol in (("foot", 1e-12), ("distance", 1e-14), ("signed_distance", 1e-14)):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=0, atol=tol * scale, err_msg=name)
    ds = np.mod(fast.s_o - slow.s_o + 0.5 * length, length) - 0.5 * length  # (s_o = 0 and L_o are one point)
    assert np.abs(ds).max() <= 1e-12 * length
    np.testing.assert_allclose(fast.phi, slow.phi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.kappa_o, slow.kappa_o, rtol=1e-10, atol=0)


def test_circle_closed_form_projection_equals_the_general_search() -> None:
    """Boundary.project of a circle (closed form) against the general candidates + Newton
    search on the same boundary (and on the circle built as an equal-axes ellipse)."""
    R, c = 0.025, (0.08, 0.08)
    q = np.asarray(c) + 0.06 * np.random.default_rng(6).standard_normal((1000, 2))
    b = circle(R, c)
    _same_projection(b.project(q), b._project_search(q, 4), b.length, R)
    _same_projection(b.project(q), ellipse(R, R, c).project(q), b.length, R)


@pytest.mark.parametrize("a,b,center,angle", [(8.0, 4.0, (0.0, 0.0), 0.0), (0.03, 0.02, (0.08, 0.08), 0.7),
                                              (4.0, 8.0, (1.0, -2.0), -2.0), (5.0, 5.0, (0.0, 0.0), 0.3)])
def test_ellipse_projection_equals_the_general_search(a: float, b: float, center: tuple[float, float],
                                                      angle: float) -> None:
    """The ellipse's root-bracketing projection against the general search: queries outside,
    inside and near the centre (the global closest point everywhere)."""
    e = ellipse(a, b, center, angle)
    rng = np.random.default_rng(0)
    big, small = max(a, b), min(a, b)
    q = np.vstack([np.asarray(center) + rng.uniform(-3 * big, 3 * big, size=(1500, 2)),
                   np.asarray(center) + rng.uniform(-0.3 * small, 0.3 * small, size=(300, 2))])
    _same_projection(e.project(q), e._project_search(q, 4), e.length, big)


def test_ellipse_projection_on_the_axes_and_at_the_centre() -> None:
    """Closed forms: on the major axis inside the evolute the foot is the nearest vertex's
    neighbourhood point of Eberly's formula; at the centre the foot is a minor-axis end."""
    a, b = 8.0, 4.0
    e = ellipse(a, b)
    pr = e.project(np.array([[0.0, 0.0], [20.0, 0.0], [0.0, -9.0], [1.0, 0.0]]))
    np.testing.assert_allclose(np.abs(pr.foot[0]), [0.0, b], atol=1e-12)
    np.testing.assert_allclose(pr.foot[1], [a, 0.0], atol=1e-12)
    np.testing.assert_allclose(pr.foot[2], [0.0, -b], atol=1e-12)
    x0 = a * 1.0 / (a * a - b * b) * a  # Eberly: x0 = a^2 y0 / (a^2 - b^2) inside the evolute
    np.testing.assert_allclose(pr.foot[3], [x0, b * np.sqrt(1 - (x0 / a) ** 2)], atol=1e-12)
    np.testing.assert_allclose(pr.distance, [b, 12.0, 5.0, np.hypot(x0 - 1.0, b * np.sqrt(1 - (x0 / a) ** 2))],
                               atol=1e-12)


def test_lockstep_loop_same_with_and_without_kernels() -> None:
    """A stretch of the paper's lock-step loop (through first contact) gives the same states
    with the kernels as with the numpy code, to rounding amplified over the steps."""
    boundary = PAPER.object.boundary()
    gains = PAPER.feedback_gains

    def run() -> np.ndarray:
        session = LoopSession(RodSystem(PAPER.rod, Obstacle(boundary)), PAPER.loop)
        for _ in range(120):
            obs = session.observe()
            c = sense(obs.shape, boundary, obs.radius, tol=PAPER.sensing.contact_tolerance)
            session.advance(feedback_at_joints(PAPER.rod, gains, c.rho, c.alpha))
        return np.concatenate([session.state.theta, [session.iterations]])

    ref, got = _both(run)
    assert got[-1] == ref[-1]  # same Newton iterations
    np.testing.assert_allclose(got[:-1], ref[:-1], rtol=0, atol=1e-11)


def test_kinetic_energy_and_contact_frame_kernels() -> None:
    system, state, _ = _contact_case("euler", "none")
    ref, got = _both(lambda: system.kinetic_energy(state))
    assert got == pytest.approx(ref, rel=1e-13)
    f0, f1 = _both(lambda: system.contact_frame(state, 2e-3))
    assert f0 is not None and f1 is not None
    np.testing.assert_array_equal(f1.rows, f0.rows)
    for name in ("foot", "normal", "tangent"):
        np.testing.assert_allclose(getattr(f1, name), getattr(f0, name), rtol=0, atol=1e-15, err_msg=name)


def test_read_only_inputs_use_the_compiled_signature() -> None:
    """Arrays that arrive read-only (e.g. views of message buffers) are copied to the one array
    type the kernels are compiled (and cached) for, instead of compiling a second version."""
    system, state, loads = _contact_case("euler", "held")
    frame = system.contact_frame(state, 2e-3)
    system.newton_system(state, state.omega, 2e-3, loads, frame)
    before = {k: len(getattr(_kernels, k).signatures) for k in ("newton_system", "joint_couple_jacobian", "frames_nodes")}
    theta, omega = state.theta.copy(), state.omega.copy()
    theta.setflags(write=False)
    omega.setflags(write=False)
    couple = np.asarray(loads.couple, dtype=float).copy()
    couple.setflags(write=False)
    ro_state = type(state)(t=state.t, theta=theta, omega=omega)
    ro_loads = type(loads)(couple=couple, node_forces=loads.node_forces, feedback=loads.feedback)
    system.newton_system(ro_state, omega, 2e-3, ro_loads, system.contact_frame(ro_state, 2e-3))
    system.kinetic_energy(ro_state)
    after = {k: len(getattr(_kernels, k).signatures) for k in before}
    assert after == before


@pytest.mark.heavy
def test_load_sensing_loads_the_signature_the_sensing_uses() -> None:
    """contact.load_sensing (the ROS boundary sensor's start-up) loads the one compiled signature
    that sensing a rod state uses later: a fresh process senses the paper's arm without
    compiling or loading another."""
    import subprocess
    import sys

    code = """
from contgrasp_core.contact import load_sensing, sense
from contgrasp_core.rod import _kernels
from contgrasp_core.rod.session import LoopSession, sensed_shape
from contgrasp_core.scenario import PAPER
load_sensing()
loaded = list(_kernels.circle_sense.signatures)
assert len(loaded) == 1, loaded
session = LoopSession(PAPER.system(), PAPER.loop)
obs = session.observe()
sense(sensed_shape(session.system, obs), PAPER.object.boundary(), obs.radius, tol=PAPER.sensing.contact_tolerance)
assert list(_kernels.circle_sense.signatures) == loaded, _kernels.circle_sense.signatures
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
