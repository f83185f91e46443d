"""Grasp maps, Gramian and Q1..Q3 against closed forms and Prop. 4.1."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contgrasp_core.arm import shape_from_curvature
from contgrasp_core.boundary import circle, ellipse
from contgrasp_core.contact import base_pose, offset_curvature, sense
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.quality import (
    contact_weights,
    continuum_operator,
    discrete_grasp_map,
    gramian,
    grasp_quality,
    metrics_from_gramian,
    point_grasp_maps,
    quality_of_state,
    singular_value_metrics,
)

finite = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(finite, finite, st.floats(-10, 10)), min_size=1, max_size=8))
def test_GGt_depends_only_on_contact_points(pts: list[tuple[float, float, float]]) -> None:
    """G G^T = [[I2, g], [g^T, |g|^2]] with g = gamma^perp, whatever the tangent angles."""
    arr = np.array(pts)
    maps = point_grasp_maps(arr[:, :2], arr[:, 2])
    for G, (x, y, _) in zip(maps, pts, strict=True):
        g = np.array([-y, x])
        expected = np.block([[np.eye(2), g[:, None]], [g[None, :], np.array([[g @ g]])]])
        np.testing.assert_allclose(G @ G.T, expected, atol=1e-9 * (1 + g @ g))


def test_point_grasp_map_explicit() -> None:
    # contact at (0, 2) with tangent along -x (phi = pi): tangential unit force = (-1, 0),
    # normal (inward) = (0, -1); torques about the origin: r x f = (0,2) x (-1,0) = 2, (0,2) x (0,-1) = 0
    G = point_grasp_maps([[0.0, 2.0]], [np.pi])[0]
    np.testing.assert_allclose(G, [[-1, 0], [0, -1], [2, 0]], atol=1e-15)
    Gt = discrete_grasp_map([[0.0, 2.0], [1.0, 0.0]], [np.pi, 0.5])
    assert Gt.shape == (3, 4)
    # the reference point is explicit: about (0, 2) the first contact exerts no torque
    np.testing.assert_allclose(point_grasp_maps([[0.0, 2.0]], [np.pi], ref=(0.0, 2.0))[0][2], 0.0, atol=1e-15)


def test_singular_value_metrics_shape_driven() -> None:
    m = singular_value_metrics(np.diag([3.0, 2.0, 0.5]))
    assert m["sigma_min"] == 0.5 and m["volume"] == pytest.approx(3.0) and m["isotropy"] == pytest.approx(0.5 / 3)
    one = singular_value_metrics(discrete_grasp_map([[1.0, 0.0]], [0.0]))  # 3 x 2: cannot span 3-D wrenches
    assert one["sigma_min"] == 0.0 and one["volume"] == 0.0 and len(one["singular_values"]) == 3
    assert len(singular_value_metrics(np.ones((2, 5)))["singular_values"]) == 2


@pytest.mark.parametrize("rho", [0.5, 1.0])
def test_full_wrap_of_a_circle(rho: float) -> None:
    """W = diag(l, l, R^2 l), l the contact length in ARM arclength = 2 pi (R + rho)."""
    R = 3.0
    b = circle(R)
    L = 2 * np.pi * (R + rho)
    s = np.linspace(0, L, 801)
    shape = shape_from_curvature(s, offset_curvature(b, s, rho, 0.0), base_pose(b, rho, np.pi / 2, 0.0))
    state = sense(shape, b, np.full_like(s, rho), tol=1e-6)
    assert np.all(state.in_contact)
    q = quality_of_state(state, b)
    np.testing.assert_allclose(q.W, np.diag([L, L, R**2 * L]), atol=1e-9 * L * R**2)
    assert q.contact_length == pytest.approx(L, rel=1e-12)
    assert q.Q1 == pytest.approx(L if R > 1 else R**2 * L)
    assert q.Q2 == pytest.approx(R**2 * L**3, rel=1e-9)
    assert q.Q3 == pytest.approx(1 / R**2, rel=1e-9)


def test_partial_contact_boundaries_interpolated_second_order() -> None:
    """Contact set [a, b] inside cells: W entries converge at second order to the closed form."""
    R, a, bnd = 2.0, 0.37, 4.11
    errors = []
    for n in (41, 81, 161):
        s = np.linspace(0, 6.0, n)
        gamma = R * np.stack([np.cos(s / R), np.sin(s / R)], -1)
        phi = s / R + np.pi / 2
        delta = np.minimum(s - a, bnd - s)  # >= 0 exactly on [a, b]
        W, length = gramian(s, gamma, phi, delta)
        exact = np.array(
            [
                [bnd - a, 0.0, R * R * (np.cos(bnd / R) - np.cos(a / R))],
                [0.0, bnd - a, R * R * (np.sin(bnd / R) - np.sin(a / R))],
                [0.0, 0.0, R * R * (bnd - a)],
            ]
        )
        exact[2, :2] = exact[:2, 2]
        assert length == pytest.approx(bnd - a, rel=1e-12)  # delta is linear: cuts are exact
        errors.append(np.max(np.abs(W - exact)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 1.8), orders


def test_prop2_singular_values_equal_sqrt_eigenvalues() -> None:
    b = ellipse(8.0, 4.0)
    s = np.linspace(0, 20.0, 301)
    kappa = offset_curvature(b, s, 1.0, 1.0) + 0.02 * np.sin(s)
    state = sense(shape_from_curvature(s, kappa, base_pose(b, 1.0, 1.5, 1.0)), b, 1.0, tol=0.05)
    phi = b.tangent_angle(state.s_o)
    op = continuum_operator(s, state.foot, phi, state.delta, tol=0.05)
    W, _ = gramian(s, state.foot, phi, state.delta, tol=0.05)
    sv = np.sort(np.linalg.svd(op, compute_uv=False))
    np.testing.assert_allclose(sv, np.sqrt(np.linalg.eigvalsh(W)), rtol=1e-10)


def test_discrete_map_converges_to_continuum() -> None:
    """(l/n) G~ G~^T with n evenly spaced contacts -> W (midpoint rule, second order)."""
    R, length = 2.0, 5.0
    ref = metrics_from_gramian(
        np.array(
            [
                [length, 0, R * R * (np.cos(length / R) - 1)],
                [0, length, R * R * np.sin(length / R)],
                [R * R * (np.cos(length / R) - 1), R * R * np.sin(length / R), R * R * length],
            ]
        )
    )
    errs = []
    for n in (10, 20, 40, 80):
        sm = (np.arange(n) + 0.5) * length / n
        Gt = discrete_grasp_map(R * np.stack([np.cos(sm / R), np.sin(sm / R)], -1), sm / R + np.pi / 2)
        errs.append(np.max(np.abs((length / n) * Gt @ Gt.T - ref.W)))
        disc = singular_value_metrics(np.sqrt(length / n) * Gt)
        np.testing.assert_allclose(np.sort(disc["singular_values"]) ** 2, np.linalg.eigvalsh((length / n) * Gt @ Gt.T), rtol=1e-9)
    assert errs[-1] < 1e-3 and np.all(np.diff(np.log2(errs)) < -1.8)


def test_rotation_invariance() -> None:
    """Rotating object and arm together about the reference point leaves Q1..Q3 unchanged."""
    vals = []
    for ang in (0.0, 0.9, 2.5):
        b = ellipse(8.0, 4.0, angle=ang)
        s = np.linspace(0, 20.0, 301)
        kappa = offset_curvature(b, s, 1.0, 2.0) + 0.02 * np.cos(s)
        state = sense(shape_from_curvature(s, kappa, base_pose(b, 1.0, 1.5, 2.0)), b, 1.0, tol=0.1)
        q = quality_of_state(state, b)
        vals.append([q.Q1, q.Q2, q.Q3])
    np.testing.assert_allclose(vals[1], vals[0], rtol=1e-7)
    np.testing.assert_allclose(vals[2], vals[0], rtol=1e-7)


def test_no_contact_and_bad_input() -> None:
    s = np.linspace(0, 1, 11)
    q = grasp_quality(s, np.ones((11, 2)), np.zeros(11), -np.ones(11))
    assert not q.has_contact and q.Q1 == q.Q2 == q.Q3 == 0.0
    with pytest.raises(InvalidParameterError):
        contact_weights(s, np.zeros(10))
    with pytest.raises(InvalidParameterError):
        contact_weights(s, np.zeros(11), tol=-1.0)
    with pytest.raises(InvalidParameterError):
        gramian(s, np.ones((11, 3)), np.zeros(11), np.zeros(11))
    with pytest.raises(InvalidParameterError):
        gramian(s, np.full((11, 2), np.nan), np.zeros(11), np.zeros(11))
    with pytest.raises(InvalidParameterError):
        metrics_from_gramian(np.ones((3, 2)))
    with pytest.raises(InvalidParameterError):
        point_grasp_maps([[0.0, 1.0]], [0.0], ref=(0.0,))


def test_weighted_gramian_of_an_evenly_loaded_full_wrap() -> None:
    """n points evenly around a circle of radius R about the reference, each weighted f (a
    force-weighted grasp): the off-diagonal terms cancel and ``W = n f diag(1, 1, R^2)``."""
    import numpy as np

    from contgrasp_core.quality import weighted_gramian

    n, radius, f = 64, 0.7, 0.3
    ang = 2 * np.pi * np.arange(n) / n
    points = radius * np.stack([np.cos(ang), np.sin(ang)], axis=1) + np.array([1.0, -2.0])
    w = weighted_gramian(points, ang + 0.5 * np.pi, np.full(n, f), ref=(1.0, -2.0))
    np.testing.assert_allclose(w, n * f * np.diag([1.0, 1.0, radius**2]), atol=1e-12)
