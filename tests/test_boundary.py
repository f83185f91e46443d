"""Boundaries against closed forms (circle, ellipse, polar curvature) and identities."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from matplotlib.path import Path
from scipy.special import ellipe, ellipeinc

from contgrasp_core.boundary import (
    circle,
    deformed_circle,
    ellipse,
    fourier_polar,
    from_points,
    load_points,
)
from contgrasp_core.errors import (
    DegenerateBoundaryError,
    InvalidParameterError,
    NotClosedError,
    SelfIntersectionError,
)


def test_circle_closed_forms() -> None:
    R, c = 2.5, np.array([1.0, -2.0])
    b = circle(R, c)
    assert b.length == pytest.approx(2 * np.pi * R, rel=1e-14)
    s = np.linspace(-7.0, 40.0, 97)
    expected = c + R * np.stack([np.cos(s / R), np.sin(s / R)], axis=-1)
    np.testing.assert_allclose(b.point(s), expected, atol=1e-12)
    np.testing.assert_allclose(b.curvature(s), 1.0 / R, rtol=1e-12)
    np.testing.assert_allclose(b.tangent_angle(s), s / R + np.pi / 2, atol=1e-12)
    np.testing.assert_allclose(b.curvature_derivative(s), 0.0, atol=1e-12)
    # inward normal points to the centre
    np.testing.assert_allclose(b.point(s) + R * b.normal(s), np.broadcast_to(c, (len(s), 2)), atol=1e-12)


def test_circle_projection_closed_form() -> None:
    R, c = 3.0, np.array([0.5, 0.25])
    b = circle(R, c)
    rng = np.random.default_rng(1)
    q = c + rng.uniform(-10, 10, size=(500, 2))
    q = q[np.abs(np.hypot(*(q - c).T) - R) > 1e-3]
    pr = b.project(q)
    rq = np.hypot(*(q - c).T)
    np.testing.assert_allclose(pr.distance, np.abs(rq - R), atol=1e-11)
    np.testing.assert_allclose(pr.foot, c + R * (q - c) / rq[:, None], atol=1e-11)
    np.testing.assert_array_equal(pr.side, np.where(rq > R, 1, -1))
    np.testing.assert_allclose(pr.signed_distance, rq - R, atol=1e-11)
    ang = np.mod(np.arctan2(*(q - c).T[::-1]), 2 * np.pi)
    np.testing.assert_allclose(pr.s_o, R * ang, atol=1e-9)


def test_ellipse_perimeter_and_arclength_against_elliptic_integrals() -> None:
    a, b_ = 8.0, 4.0
    e = ellipse(a, b_)
    m = 1.0 - (b_ / a) ** 2
    assert e.length == pytest.approx(4 * a * ellipe(m), rel=1e-13)
    # s(t) from t = 0 (the point (a, 0)) is a [E(pi/2 | m) - E(pi/2 - t | m)]
    t = np.linspace(0.0, np.pi / 2, 13)
    s = a * (ellipe(m) - ellipeinc(np.pi / 2 - t, m))
    np.testing.assert_allclose(e.point(s), np.stack([a * np.cos(t), b_ * np.sin(t)], -1), atol=1e-11)
    kappa_exact = a * b_ / (a**2 * np.sin(t) ** 2 + b_**2 * np.cos(t) ** 2) ** 1.5
    np.testing.assert_allclose(e.curvature(s), kappa_exact, rtol=1e-11)


def test_rotated_ellipse_axis_projection() -> None:
    ang = 0.7
    e = ellipse(5.0, 2.0, center=(1.0, 1.0), angle=ang)
    u = np.array([np.cos(ang), np.sin(ang)])
    q = np.array([1.0, 1.0]) + np.outer([7.0, 9.0, 5.5], u)
    pr = e.project(q)
    np.testing.assert_allclose(pr.distance, [2.0, 4.0, 0.5], atol=1e-11)
    np.testing.assert_allclose(pr.foot, np.broadcast_to(np.array([1.0, 1.0]) + 5.0 * u, (3, 2)), atol=1e-10)


@pytest.mark.parametrize("make", [lambda: ellipse(8, 4), lambda: deformed_circle(), lambda: circle(1.3)])
def test_arclength_identities(make) -> None:  # type: ignore[no-untyped-def]
    """|dgamma/ds| = 1, dphi/ds = kappa, dkappa/ds matches differences, phi(s+L) = phi(s)+2pi."""
    b = make()
    s = np.linspace(0.0, b.length, 301)
    h = 1e-4
    dgamma = (b.point(s + h) - b.point(s - h)) / (2 * h)
    np.testing.assert_allclose(np.hypot(*dgamma.T), 1.0, atol=1e-7)
    np.testing.assert_allclose(dgamma, b.tangent(s), atol=1e-7)
    dphi = (b.tangent_angle(s + h) - b.tangent_angle(s - h)) / (2 * h)
    np.testing.assert_allclose(dphi, b.curvature(s), atol=1e-6)
    dk = (b.curvature(s + h) - b.curvature(s - h)) / (2 * h)
    np.testing.assert_allclose(dk, b.curvature_derivative(s), atol=1e-6)
    np.testing.assert_allclose(b.tangent_angle(s + b.length), b.tangent_angle(s) + 2 * np.pi, atol=1e-12)
    # the turning angle over one traversal is exactly 2 pi (simple, counter-clockwise)
    assert b.tangent_angle(b.length - 1e-12) - b.tangent_angle(0.0) == pytest.approx(2 * np.pi, abs=1e-9)


def test_deformed_circle_formula_and_concavity() -> None:
    R, amp, m = 5.0, 0.15, 3
    b = deformed_circle(R, amp, m)
    # independent polar-curve curvature (r^2 + 2 r'^2 - r r'') / (r^2 + r'^2)^(3/2)
    s = np.linspace(0, b.length, 400, endpoint=False)
    p = b.point(s)
    t = np.arctan2(p[:, 1], p[:, 0])
    r = R * (1 + amp * np.cos(m * t))
    np.testing.assert_allclose(np.hypot(*p.T), r, atol=1e-11)
    r1 = -R * amp * m * np.sin(m * t)
    r2 = -R * amp * m**2 * np.cos(m * t)
    kappa = (r**2 + 2 * r1**2 - r * r2) / (r**2 + r1**2) ** 1.5
    np.testing.assert_allclose(b.curvature(s), kappa, rtol=1e-10, atol=1e-12)
    assert b.curvature(s).min() < 0.0 < b.curvature(s).max()


def _inside(boundary, q):  # type: ignore[no-untyped-def]
    _, pts = boundary.sample(4000)
    return Path(pts).contains_points(q)


@pytest.mark.heavy
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    coeffs=st.lists(st.floats(-0.08, 0.08), min_size=2, max_size=10),
    seed=st.integers(0, 2**31 - 1),
    scale=st.floats(0.5, 20.0),
)
def test_projection_properties_random_smooth_boundaries(coeffs: list[float], seed: int, scale: float) -> None:
    """Foot on the curve, normality, global optimality (dense brute force) and the side."""
    half = len(coeffs) // 2
    b = fourier_polar(scale, coeffs[:half], coeffs[half:], center=(0.3 * scale, -0.1 * scale))
    rng = np.random.default_rng(seed)
    q = np.array([0.3 * scale, -0.1 * scale]) + rng.uniform(-3 * scale, 3 * scale, size=(64, 2))
    pr = b.project(q)
    np.testing.assert_allclose(b.point(pr.s_o), pr.foot, atol=1e-9 * scale)
    rel = q - pr.foot
    np.testing.assert_allclose(np.hypot(*rel.T), pr.distance, atol=1e-12 * scale)
    tang = b.tangent(pr.s_o)
    assert np.all(np.abs(np.sum(rel * tang, axis=1)) <= 1e-8 * scale * (1 + pr.distance / scale))
    _, dense = b.sample(20000)
    brute = np.min(np.hypot(q[:, None, 0] - dense[None, :, 0], q[:, None, 1] - dense[None, :, 1]), axis=1)
    assert np.all(pr.distance <= brute + 1e-9 * scale)
    # the nearest sample is within half a sample spacing (in arclength) of the true foot
    assert np.all(pr.distance >= brute - 0.5 * b.length / 20000)
    far = pr.distance > 1e-3 * scale
    np.testing.assert_array_equal((pr.side < 0)[far], _inside(b, q)[far])


def test_from_points_circle_samples() -> None:
    R = 4.0
    th = np.linspace(0, 2 * np.pi, 121)
    pts = np.stack([R * np.cos(th), R * np.sin(th)], -1)  # last repeats first: closed
    b = from_points(pts)
    assert b.length == pytest.approx(2 * np.pi * R, rel=1e-8)
    s = np.linspace(0, b.length, 200, endpoint=False)
    np.testing.assert_allclose(b.curvature(s), 1 / R, rtol=1e-5)
    # clockwise input is reversed to counter-clockwise (the object on the left)
    bcw = from_points(pts[::-1])
    assert np.all(bcw.curvature(s * bcw.length / b.length) > 0)


def test_prepare_builds_the_lazy_tables_and_changes_no_answer() -> None:
    """``prepare`` (a node's call on an arriving object) builds what the first query would."""
    s = np.linspace(-0.3, 0.9, 17)
    q = np.array([[0.31, 0.02], [-0.1, 0.45], [0.0, -0.2]])
    lazy, ready = deformed_circle(0.2, 0.2, 3), deformed_circle(0.2, 0.2, 3)
    assert ready.prepare() is ready and {"_t_of_s_guess", "_phi_ref", "_tree"} <= set(vars(ready))
    assert not {"_t_of_s_guess", "_phi_ref", "_tree"} & set(vars(lazy))
    np.testing.assert_array_equal(lazy.tangent_angle(s), ready.tangent_angle(s))
    np.testing.assert_array_equal(lazy.project(q).s_o, ready.project(q).s_o)


def test_from_points_rejects_bad_outlines(tmp_path) -> None:  # type: ignore[no-untyped-def]
    th = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.stack([np.cos(th), np.sin(th)], -1)
    with pytest.raises(NotClosedError, match="open polyline"):
        from_points(ring[:30])
    assert from_points(ring, closed=True).length == pytest.approx(2 * np.pi, rel=1e-5)
    bowtie = np.array([[0, 0], [2, 2], [2, 0], [1, -0.5], [0, 2], [0, 0]], float)
    with pytest.raises(SelfIntersectionError):
        from_points(bowtie)
    with pytest.raises(DegenerateBoundaryError):
        from_points(np.array([[0, 0], [1, 1], [2, 2], [3, 3], [4, 4], [0, 0]], float))
    with pytest.raises(DegenerateBoundaryError):
        from_points(np.array([[0, 0], [1, 0], [0, 1], [0, 0]], float))
    bad = ring.copy()
    bad[3, 0] = np.nan
    with pytest.raises(DegenerateBoundaryError, match="NaN"):
        from_points(bad, closed=True)
    csv = tmp_path / "outline.csv"
    csv.write_text("x,y\n" + "\n".join(f"{x},{y}" for x, y in np.vstack([ring, ring[:1]])))
    assert from_points(load_points(str(csv))).length == pytest.approx(2 * np.pi, rel=1e-5)
    csv.write_text("x,y\n1,2\nfoo,bar\n")
    with pytest.raises(DegenerateBoundaryError, match=":3"):
        load_points(str(csv))


def test_invalid_parameters() -> None:
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(InvalidParameterError):
            circle(bad)
    with pytest.raises(InvalidParameterError):
        ellipse(1.0, -2.0)
    with pytest.raises(InvalidParameterError):
        circle(1.0, center=(0.0, 0.0, 1.0))
    with pytest.raises(DegenerateBoundaryError):
        fourier_polar(1.0, [1.2])
    with pytest.raises(InvalidParameterError):
        deformed_circle(5.0, amplitude=1.5)
    with pytest.raises(InvalidParameterError):
        circle(1.0).project(np.array([[np.nan, 0.0]]))


def test_projection_reports_tangent_angle_and_curvature_at_the_foot() -> None:
    b = deformed_circle()
    q = np.random.default_rng(3).uniform(-12, 12, size=(200, 2))
    pr = b.project(q)
    np.testing.assert_allclose(pr.phi, b.tangent_angle(pr.s_o), atol=1e-10)
    np.testing.assert_allclose(pr.kappa_o, b.curvature(pr.s_o), atol=1e-9)
