"""Contact kinematics: ODE (eq. (8), the contact kinematics) vs geometric sensing, closed forms, validity."""

from __future__ import annotations

import numpy as np
import pytest

from contgrasp_core.arm import ArmShape, BasePose, shape_from_curvature
from contgrasp_core.boundary import circle, deformed_circle, ellipse
from contgrasp_core.contact import (
    base_pose,
    initial_state,
    integrate_contact,
    offset_curvature,
    sense,
    shadow_geometry,
    shape_from_contact,
)
from contgrasp_core.contact import _unwrap
from contgrasp_core.errors import ContactValidityError, InvalidParameterError
from contgrasp_core.rod import Obstacle


@pytest.mark.parametrize(
    "boundary,rho0,alpha0,s_o0",
    [(circle(5.0), 1.0, 1.55, 0.3), (ellipse(8.0, 4.0), 1.2, 1.6, 2.0), (deformed_circle(), 0.8, 1.5, 4.0)],
    ids=["circle", "ellipse", "deformed"],
)
def test_ode_agrees_with_geometry(boundary, rho0, alpha0, s_o0) -> None:  # type: ignore[no-untyped-def]
    """Two independent routes to (rho, alpha, s_o): ODE vs shape + closest points."""
    L = boundary.length / 2
    s = np.linspace(0, L, 401)
    kappa = offset_curvature(boundary, s, rho0, s_o0) + 0.01 * np.sin(2 * np.pi * s / L)
    ode = integrate_contact(s, kappa, boundary, rho0, alpha0, s_o0)
    shape = shape_from_curvature(s, kappa, base_pose(boundary, rho0, alpha0, s_o0))
    geo = sense(shape, boundary, 0.3)
    assert np.all(geo.valid)
    assert np.max(np.abs(ode.rho - geo.rho)) / L < 1e-6
    assert np.max(np.abs(ode.alpha - geo.alpha)) < 1e-6
    assert np.max(np.abs(ode.s_o - geo.s_o)) / L < 1e-6
    np.testing.assert_allclose(geo.nu_o, np.sin(geo.alpha) / (1 + geo.rho * geo.kappa_o))
    # reverse map: (rho, alpha, s_o) -> arm shape reproduces the integrated shape
    back = shape_from_contact(s, ode.rho, ode.alpha, ode.s_o, boundary)
    assert np.max(np.hypot(*(back.r - shape.r).T)) / L < 1e-6
    assert np.max(np.abs(back.theta - shape.theta)) < 1e-6


@pytest.mark.parametrize("rho", [0.2, 1.0, 3.0])
def test_constant_distance_around_a_circle(rho: float) -> None:
    """kappa = 1/(R + rho) with alpha0 = pi/2 keeps rho constant and alpha = pi/2 exactly."""
    R = 5.0
    b = circle(R, center=(1.0, 2.0))
    s = np.linspace(0, 0.9 * 2 * np.pi * (R + rho), 301)
    kappa = offset_curvature(b, s, rho, 1.0)
    np.testing.assert_allclose(kappa, 1.0 / (R + rho), rtol=1e-13)
    ode = integrate_contact(s, kappa, b, rho, np.pi / 2, 1.0)
    np.testing.assert_allclose(ode.rho, rho, atol=1e-12)
    np.testing.assert_allclose(ode.alpha, np.pi / 2, atol=1e-12)
    np.testing.assert_allclose(ode.s_o, 1.0 + s * R / (R + rho), atol=1e-10)
    shape = shape_from_curvature(s, kappa, base_pose(b, rho, np.pi / 2, 1.0))
    geo = sense(shape, b, np.full_like(s, rho))
    np.testing.assert_allclose(geo.rho, rho, atol=1e-10)
    np.testing.assert_allclose(geo.alpha, np.pi / 2, atol=1e-10)
    np.testing.assert_allclose(geo.delta, 0.0, atol=1e-10)
    assert np.all(geo.in_contact | (geo.delta > -1e-9))


@pytest.mark.parametrize("projection", ["boundary", "obstacle"])
def test_sense_on_a_circle_matches_closed_forms(projection: str) -> None:
    """Points at distance d and polar angle psi from a circle's centre c, with arm angle theta:
    foot = c + R u (u = (cos psi, sin psi)), s_o = R psi, rho = d - R, alpha = psi + pi - theta
    (the inward normal points along -u), normal_out = u = (x - c)/|x - c|, kappa_o = 1/R,
    foot_turn = (1/R)/(1 + rho/R) = 1/d and nu_o = sin(alpha) R/d; eq. (5) and Definition 1.
    Both projections sense() accepts (Boundary.project and the rod's Obstacle) give them."""
    R, c = 0.7, np.array([0.3, -1.2])
    b = circle(R, center=tuple(c))
    rng = np.random.default_rng(11)
    n = 40
    psi = np.sort(rng.uniform(0.05, 2 * np.pi - 0.05, n))  # increasing: s_o needs no unwrapping
    d = rng.uniform(0.3 * R, 3.0 * R, n)  # inside and outside the object
    theta = rng.uniform(-3.0, 3.0, n)
    u = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    x = c + d[:, None] * u
    radius = rng.uniform(0.0, 0.5, n)
    shape = ArmShape(s=np.arange(n, dtype=float), r=x, theta=theta)
    geo = sense(shape, b if projection == "boundary" else Obstacle(b), radius, tol=0.05)
    rho = d - R
    alpha = np.mod(psi + np.pi - theta + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(geo.rho, rho, atol=1e-12)
    np.testing.assert_allclose(geo.alpha, alpha, atol=1e-12)
    assert np.all((geo.alpha >= -np.pi) & (geo.alpha < np.pi))
    np.testing.assert_allclose(geo.s_o, R * psi, atol=1e-12)
    np.testing.assert_allclose(geo.foot, c + R * u, atol=1e-12)
    np.testing.assert_allclose(geo.kappa_o, 1.0 / R, rtol=1e-12)
    np.testing.assert_allclose(geo.normal_out, (x - c) / np.hypot(*(x - c).T)[:, None], atol=1e-12)
    np.testing.assert_allclose(geo.foot_turn, (1.0 / R) / (1.0 + rho / R), rtol=1e-12)
    np.testing.assert_allclose(geo.foot_turn, 1.0 / d, rtol=1e-12)
    np.testing.assert_allclose(geo.nu_o, np.sin(alpha) * R / d, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(geo.delta, radius - rho, atol=1e-12)
    np.testing.assert_array_equal(geo.in_contact, radius - rho >= -0.05)
    np.testing.assert_array_equal(geo.valid, (rho > 0) & (alpha > 0) & (alpha < np.pi))
    np.testing.assert_array_equal(geo.s, shape.s)
    assert geo.tol == 0.05


def test_sense_outward_normal_points_from_the_foot_to_the_arm() -> None:
    """On any boundary, r - foot = rho normal_out (the foot is the closest point)."""
    b = ellipse(3.0, 1.5, center=(0.5, 0.2), angle=0.4)
    s = np.linspace(0, 6, 50)
    shape = shape_from_curvature(s, np.full_like(s, 0.25), BasePose(4.0, -1.0, np.pi / 2))
    for obj in (b, Obstacle(b)):
        geo = sense(shape, obj, 0.1)
        np.testing.assert_allclose(shape.r - geo.foot, geo.rho[:, None] * geo.normal_out, atol=1e-9)
        np.testing.assert_allclose(np.hypot(*geo.normal_out.T), 1.0, atol=1e-12)


@pytest.mark.parametrize("start,crosses", [(0.5 * np.pi, False), (-0.25, True)], ids=["no-seam", "across-the-seam"])
def test_sense_unwraps_s_o_like_numpy(start: float, crosses: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """s_o is np.unwrap of the projection's arclengths (sense skips the call when no step can
    cross the seam s_o = 0, which must not change a bit). Against a circle Boundary this is the
    numpy path (kernels off); its compiled twin is compared with it in tests/test_kernels.py."""
    from contgrasp_core.rod import _kernels

    b = circle(1.0)
    s = np.linspace(0, 0.5 * np.pi * 1.2, 80)  # a quarter turn at distance 0.2, counter-clockwise
    base = BasePose(1.2 * np.cos(start), 1.2 * np.sin(start), start + np.pi / 2)
    shape = shape_from_curvature(s, np.full_like(s, 1 / 1.2), base)
    for obj in (b, Obstacle(b)):
        wrapped = obj.project(shape.r).s_o
        assert bool(np.any(np.diff(wrapped) < 0)) == crosses
        monkeypatch.setattr(_kernels, "ENABLED", not isinstance(obj, type(b)))
        geo = sense(shape, obj, 0.1)
        monkeypatch.undo()
        np.testing.assert_array_equal(geo.s_o, np.unwrap(wrapped, period=b.length))
        assert np.all(np.diff(geo.s_o) > 0)


def test_unwrap_is_numpys_bit_for_bit() -> None:
    """The written-out unwrap equals np.unwrap exactly: random walks around the seam, steps of
    exactly half a period (numpy's boundary rule), single points, NaN."""
    rng = np.random.default_rng(7)
    for trial in range(3000):
        length = float(rng.uniform(0.01, 10.0))
        n = int(rng.integers(1, 40))
        s_o = np.mod(np.cumsum(rng.normal(0.0, length / 4, n)), length)
        if trial % 5 == 0 and n > 2:
            s_o[2] = s_o[1] + (length / 2 if trial % 2 else -length / 2)
        if trial % 97 == 0:
            s_o[rng.integers(n)] = np.nan
        want = np.unwrap(s_o, period=length) if np.any(np.abs(np.diff(s_o)) >= 0.5 * length) else s_o
        np.testing.assert_array_equal(_unwrap(s_o, length), want)


@pytest.mark.parametrize("make", [lambda: circle(0.025, (0.03, 0.05)), lambda: ellipse(0.03, 0.02, (0.03, 0.05), 0.3),
                                  lambda: deformed_circle(0.025, 0.003, 3, 0.2, (0.03, 0.05))],
                         ids=["circle", "ellipse", "deformed"])
def test_shadow_geometry_is_senses_fields_bit_for_bit(make) -> None:  # type: ignore[no-untyped-def]
    """What the feedback's Newton iterations read (shadow_geometry) is what sense() returns."""
    obstacle = Obstacle(make())
    s = np.linspace(0.0, 0.2, 101)
    shape = shape_from_curvature(s, np.full_like(s, 12.0), BasePose(0.0, 0.0, 0.3))
    geo = sense(shape, obstacle, 0.004)
    rho, alpha, kappa_o, foot_turn, normal_out = shadow_geometry(shape.r, shape.theta, obstacle)
    for got, want in ((rho, geo.rho), (alpha, geo.alpha), (kappa_o, geo.kappa_o), (foot_turn, geo.foot_turn),
                      (normal_out, geo.normal_out)):
        np.testing.assert_array_equal(got, want)


def test_sense_rejects_what_is_not_an_object() -> None:
    shape = ArmShape(s=np.zeros(1), r=np.zeros((1, 2)), theta=np.zeros(1))
    with pytest.raises(InvalidParameterError, match="Boundary or an Obstacle"):
        sense(shape, "circle", 0.1)  # type: ignore[arg-type]


def test_contact_set_and_tolerance() -> None:
    b = circle(2.0)
    s = np.linspace(0, 3, 60)
    shape = shape_from_curvature(s, np.full_like(s, 1 / 2.5), BasePose(2.5, 0.0, np.pi / 2))
    radius = np.linspace(0.6, 0.4, len(s))  # delta = radius - 0.5 crosses zero mid-arm
    strict = sense(shape, b, radius)
    np.testing.assert_array_equal(strict.in_contact, radius - 0.5 >= 0)
    loose = sense(shape, b, radius, tol=0.05)
    np.testing.assert_array_equal(loose.in_contact, radius - 0.5 >= -0.05)


def test_centreline_inside_object_gives_negative_rho() -> None:
    b = circle(1.0)
    shape = shape_from_curvature(np.linspace(0, 1, 5), np.zeros(5), BasePose(0.5, -0.5, np.pi / 2))
    geo = sense(shape, b, 0.1)
    inside = np.hypot(*shape.r.T) < 1.0
    np.testing.assert_array_equal(geo.rho < 0, inside)
    assert not np.any(geo.valid[inside])


def test_straight_arm_hits_circle_where_the_line_does() -> None:
    """Leaving the admissible region is reported at the right arclength (line-circle hit)."""
    R = 2.0
    b = circle(R)
    rho0, alpha0 = 1.0, np.pi / 6
    base = base_pose(b, rho0, alpha0, 0.0)
    p0 = np.array([base.x, base.y])
    a = np.array([np.cos(base.theta), np.sin(base.theta)])
    # |p0 + s a| = R  ->  s^2 + 2 (p0.a) s + |p0|^2 - R^2 = 0
    pa = p0 @ a
    s_hit = -pa - np.sqrt(pa**2 - (p0 @ p0 - R**2))
    s = np.linspace(0, 4.0, 81)
    with pytest.raises(ContactValidityError) as info:
        integrate_contact(s, np.zeros_like(s), b, rho0, alpha0, 0.0)
    assert info.value.condition == "rho > 0"
    assert info.value.s == pytest.approx(s_hit, abs=1e-6)
    assert f"s = {s_hit:.4g}"[:8] in str(info.value)


def test_initial_state_round_trip_and_bad_states() -> None:
    b = ellipse(8.0, 4.0)
    rho0, alpha0, s_o0 = 1.7, 1.2, 5.0
    base = base_pose(b, rho0, alpha0, s_o0)
    got = initial_state(b, base)
    np.testing.assert_allclose(got, (rho0, alpha0, s_o0), atol=1e-10)
    with pytest.raises(ContactValidityError, match="inside the object"):
        initial_state(b, BasePose(1.0, 0.5, 0.0))
    with pytest.raises(ContactValidityError, match=r"\(0, pi\)"):
        initial_state(b, BasePose(10.0, 0.0, -np.pi / 2))  # heading puts the object on the right
    s = np.linspace(0, 1, 11)
    for rho, alpha in [(0.0, 1.5), (-1.0, 1.5), (1.0, 0.0), (1.0, np.pi), (1.0, 4.0), (np.nan, 1.0)]:
        with pytest.raises(ContactValidityError):
            integrate_contact(s, np.zeros_like(s), b, rho, alpha, 0.0)
    # 1 + rho kappa_o <= 0: too far out in the deformed circle's concave part
    d = deformed_circle()
    s_concave = d.sample(2000)[0][np.argmin(d.curvature(d.sample(2000)[0]))]
    with pytest.raises(ContactValidityError, match="1 \\+ rho kappa_o"):
        integrate_contact(s, np.zeros_like(s), d, 9.0, 1.5, s_concave)
