"""The wrench capacity of a continuum contact, Q_H (docs/holding.md eqs. (M1)-(M3)), against
closed forms: a full wrap of a circle, the frictionless torque, a contact that can only push,
invariance under a rigid rotation, monotonicity in mu, and bad input."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.holding.measure import support, wrench_capacity, wrench_generators
from contgrasp_core.quality import contact_weights

R = 0.025


def arc(start: float, stop: float, n: int = 2001, centre: tuple[float, float] = (0.0, 0.0)) -> dict[str, np.ndarray]:
    """An arm lying on the circle of radius R (counter-clockwise from polar angle ``start`` to
    ``stop``), in contact all along: its grid, feet, tangent angles and depth."""
    ang = np.linspace(start, stop, n)
    s = R * (ang - start)
    gamma = np.stack([centre[0] + R * np.cos(ang), centre[1] + R * np.sin(ang)], axis=-1)
    return {"s": s, "gamma": gamma, "phi": ang + np.pi / 2, "delta": np.zeros(n)}


def h(c: dict[str, np.ndarray], mu: float, d: list[float], ref: tuple[float, float] = (0.0, 0.0)) -> float:
    gen = wrench_generators(c["gamma"], c["phi"], mu, ref, R)
    return float(support(gen, contact_weights(c["s"], c["delta"]), [d])[0])


@pytest.mark.parametrize("mu", [0.0, 0.3, 1.0])
def test_the_full_wrap_has_the_closed_form_support(mu: float) -> None:
    """Full wrap, a = R: h = 2 R (sqrt(1 + mu^2) + mu) for every pure force, 2 pi R mu for the
    pure torque (trapezoidal quadrature of a periodic integrand with kinks: 1e-6)."""
    full = arc(0.0, 2 * np.pi)
    for angle in (0.0, 0.7, 2.0):
        assert h(full, mu, [np.cos(angle), np.sin(angle), 0.0]) == pytest.approx(2 * R * (np.hypot(1, mu) + mu), rel=1e-6)
    assert h(full, mu, [0.0, 0.0, 1.0]) == pytest.approx(2 * np.pi * R * mu, rel=1e-9, abs=1e-15)


def test_a_partial_wrap_matches_its_integral() -> None:
    """A 3 rad wrap, mu = 0.4, a mixed direction: (M2) against scipy's quad of the integrand."""
    mu, d = 0.4, np.array([0.3, -0.8, 0.5]) / np.linalg.norm([0.3, -0.8, 0.5])
    c = arc(-1.0, 2.0)

    def integrand(a: float) -> float:
        n, t = -np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        best = 0.0
        for sign in (1.0, -1.0):
            f = n + sign * mu * t
            torque = (R * np.cos(a) * f[1] - R * np.sin(a) * f[0]) / R
            best = max(best, d[0] * f[0] + d[1] * f[1] + d[2] * torque)
        return best * R

    want = quad(integrand, -1.0, 2.0, limit=200, points=np.linspace(-1.0, 2.0, 30))[0]
    assert h(c, mu, list(d)) == pytest.approx(want, rel=1e-5)


def test_the_measure_of_a_full_wrap_is_at_most_its_weakest_pure_direction_and_zero_without_friction() -> None:
    full = arc(0.0, 2 * np.pi, n=721)
    frictionless = wrench_capacity(full["s"], full["gamma"], full["phi"], full["delta"], mu=0.0, scale=R)
    assert frictionless.measure < 1e-9 and abs(frictionless.direction[2]) == pytest.approx(1.0, abs=1e-4)
    assert frictionless.contact_length == pytest.approx(2 * np.pi * R)
    rough = wrench_capacity(full["s"], full["gamma"], full["phi"], full["delta"], mu=0.5, scale=R)
    assert 0.0 < rough.measure <= min(2 * R * (np.hypot(1, 0.5) + 0.5), 2 * np.pi * R * 0.5) * (1 + 1e-6)


def test_a_contact_that_can_only_push_resists_nothing_pulled_away() -> None:
    """The upper half of the circle, frictionless: no force can pull the object up (+y), so
    Q_H = 0 (+y among its weakest directions)."""
    upper = arc(0.0, np.pi, n=401)
    cap = wrench_capacity(upper["s"], upper["gamma"], upper["phi"], upper["delta"], mu=0.0, scale=R)
    assert cap.measure < 1e-9 and h(upper, 0.0, [0.0, 1.0, 0.0]) < 1e-15  # (zero up to the end points' rounding)


def test_the_measure_grows_with_friction_and_does_not_see_a_rotation() -> None:
    c = arc(0.3, 4.5, n=401, centre=(0.08, 0.08))
    caps = [wrench_capacity(c["s"], c["gamma"], c["phi"], c["delta"], mu=mu, ref=(0.08, 0.08), scale=R).measure
            for mu in (0.2, 0.5, 1.0)]
    assert 0.0 < caps[0] < caps[1] < caps[2]
    beta = 1.1
    rot = np.array([[np.cos(beta), -np.sin(beta)], [np.sin(beta), np.cos(beta)]])
    turned = wrench_capacity(c["s"], c["gamma"] @ rot.T, c["phi"] + beta, c["delta"], mu=0.5,
                             ref=tuple(rot @ [0.08, 0.08]), scale=R)
    assert turned.measure == pytest.approx(caps[1], rel=1e-6)


def test_no_contact_is_no_capacity_and_bad_input_is_refused() -> None:
    c = arc(0.0, 1.0, n=11)
    apart = wrench_capacity(c["s"], c["gamma"], c["phi"], c["delta"] - 1.0, mu=0.5, scale=R)
    assert apart.measure == 0.0 and apart.contact_length == 0.0
    for kwargs, match in ((dict(mu=-0.1), "mu"), (dict(mu=float("nan")), "mu"), (dict(mu=0.5, scale=0.0), "torque scale"),
                          (dict(mu=0.5, ref=(0.0, float("inf"))), "reference point")):
        with pytest.raises(InvalidParameterError, match=match):
            wrench_capacity(c["s"], c["gamma"], c["phi"], c["delta"], **kwargs)  # type: ignore[arg-type]
    with pytest.raises(InvalidParameterError, match="tangent angles"):
        wrench_capacity(c["s"], c["gamma"], c["phi"][:-1], c["delta"], mu=0.5)


def test_the_friction_bound_of_a_flat_contact_is_mu_times_its_normal_bound() -> None:
    """The straight paper arm's base resting 0.1 mm deep on a circle so large that the contact is flat:
    p_max = k * 0.1 mm, nothing can pull the object towards the arm, and the tangential bound is
    mu times the normal one (to the contact's tilt, 1e-3 here)."""
    from contgrasp_core.boundary import circle
    from contgrasp_core.holding import friction_bound
    from contgrasp_core.scenario import PAPER

    rod, big, depth = PAPER.rod, 100.0, 1e-4
    r = float(rod.r_centres[0])  # (the tapered arm is thickest at its first element: it rests there deepest)
    centre = (0.5 * rod.h, -(r + big - depth))
    directions = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    p_max, bound = friction_bound(rod, circle(big, centre), np.zeros(rod.n_elements), 0.5, directions, centre, big)
    assert rod.contact_stiffness * depth * 0.99 < p_max <= rod.contact_stiffness * depth * (1 + 1e-9)
    assert bound[1] > 0 and bound[2] == 0.0 and bound[0] / bound[1] == pytest.approx(0.5, abs=1e-3)


def test_the_columns_q_h_is_of_the_maps_own_grasps() -> None:
    """Along one polar angle of the map, Q_H is taken of the grasps the map solved (each
    warm-started from the previous distance, as the map's column walk): its contact length is
    the map's (grasp_quality's, from the same solution) at every valid pose; the first pose,
    without a warm start, is the cold start's."""
    from contgrasp_core.arm import BasePose
    from contgrasp_core.holding.measure import static_capacity, static_capacity_column
    from contgrasp_core.holding.study import StudySpec
    from contgrasp_core.quality_map import _column

    ms = StudySpec(object="ellipse", arm="rod", d_steps=4).map_spec()
    column = [r for r in _column(ms, float(ms.psi[3])) if r.valid]
    assert len(column) >= 3
    caps = static_capacity_column(ms, [BasePose(*r.base) for r in column], 0.5)
    assert all(c is not None and c.measure > 0 for c in caps)
    np.testing.assert_allclose([c.contact_length for c in caps if c is not None], [r.contact_length for r in column],
                               rtol=1e-12)
    cold = static_capacity(ms, BasePose(*column[0].base), 0.5)
    assert caps[0] is not None and caps[0].measure == cold.measure and caps[0].contact_length == cold.contact_length


def test_the_cage_of_a_uniform_arm_on_the_parallel_circle_wraps_it_once() -> None:
    """(M4): a uniform arm (radius r) whose base lies on the circle's parallel curve at the close
    gap, ``rho = R + r + g_f`` from the centre, tangent to it (alpha = pi/2), is the cage's
    equilibrium all along (Prop. 5.1: eq. (20) with mu2 of (H1) is that curve's curvature), so
    an arm one parallel circumference long is in the band over its whole length and its feet
    go once round the circle: Q_H is that of the hand-built full wrap weighted per metre of arm,
    to the rod's discretisation (second order: 6e-4 at 50 elements, 16 times less at 200), at
    most its pure torque's ``mu L`` and the pure forces' ``2 rho (sqrt(1 + mu^2) + mu)``. The
    paper's law has no cage."""
    from contgrasp_core.contact import base_pose
    from contgrasp_core.holding.measure import cage_capacity
    from contgrasp_core.scenario import PAPER

    mu, r, centre, R0 = 0.5, PAPER.rod.radius_base, np.asarray(PAPER.object.center), PAPER.object.radius
    rho = R0 + r + PAPER.hold_law.close_gap
    length = 2 * np.pi * rho
    base = base_pose(PAPER.object.boundary(), rho - R0, np.pi / 2, 0.0)
    errors = []
    for n in (50, 200):
        rod = replace(PAPER.rod, radius_tip=r, length=length, base_position=(base.x, base.y), base_angle=base.theta,
                      n_elements=n)
        scenario = replace(PAPER, rod=rod, law="reactive")
        cap = cage_capacity(scenario, mu)
        s = rod.s_nodes
        ang = np.arctan2(base.y - centre[1], base.x - centre[0]) + s / rho
        gamma = centre + R0 * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        want = wrench_capacity(s, gamma, ang + np.pi / 2, np.ones_like(s), mu=mu, ref=tuple(centre), scale=R0)
        assert cap.contact_length == pytest.approx(length, rel=1e-12)
        assert 0.0 < cap.measure <= min(mu * length, 2 * rho * (np.hypot(1, mu) + mu)) * (1 + 1e-6)
        errors.append(abs(cap.measure / want.measure - 1))
    assert errors[0] < 1e-3 and errors[1] < errors[0] / 10
    with pytest.raises(InvalidParameterError, match="holding law"):
        cage_capacity(replace(scenario, law="paper"), mu)


def test_the_cage_capacity_of_a_fine_outline_of_the_circle_is_the_circles(tmp_path: Path) -> None:
    """Q_H's torques are taken about the object's reference: an outline's centroid, not its file's
    origin (0, 0), 11 cm from the paper's circle (cage Q_H 0.0031 against the circle's 0.0120
    before). A 360-point outline of the circle gives the circle's cage Q_H."""
    from contgrasp_core.holding.measure import cage_capacity
    from contgrasp_core.objects import ObjectSpec
    from contgrasp_core.scenario import PAPER

    t = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
    path = tmp_path / "circle360.csv"
    np.savetxt(path, np.c_[0.08 + 0.025 * np.cos(t), 0.08 + 0.025 * np.sin(t)], delimiter=",")
    outline = ObjectSpec.from_outline(path)
    assert outline.center == (0.0, 0.0) and outline.reference == pytest.approx((0.08, 0.08), abs=1e-9)
    assert PAPER.object.reference == PAPER.object.center
    hold = replace(PAPER, law="reactive")
    circle = cage_capacity(hold, 0.5).measure
    assert cage_capacity(hold.with_object(outline), 0.5).measure == pytest.approx(circle, rel=2e-3) and circle > 0


def test_the_cages_wrap_is_the_arc_its_band_spans_and_a_cage_that_cannot_close_is_refused() -> None:
    """(H3) on the cage at rest, before simulating: on a circle the wrap is the angle its band's
    shadow points span about the centre (the tangent turns with the polar angle). The paper's
    circle is wrapped beyond pi (the law closes); a 35 mm circle only 2.8 rad from the same base,
    so the close would never start: ``check_reach`` refuses it in one line, the paper's law passes."""
    from contgrasp_core.holding.measure import _cage_rest, cage_wrap, check_reach
    from contgrasp_core.objects import ROD_SCALE, ObjectSpec
    from contgrasp_core.scenario import PAPER

    hold = replace(PAPER, law="reactive")
    law, rest = _cage_rest(hold, "clearance")
    m, s = hold.rod, law.settings
    band = np.flatnonzero(rest.signed_distance - m.radius(m.s_nodes) <= s.clearance + s.band)
    polar = np.unwrap(np.arctan2(*(rest.foot[band] - np.asarray(PAPER.object.center)).T[::-1]))
    assert cage_wrap(hold) == pytest.approx(polar[-1] - polar[0], abs=1e-9) and cage_wrap(hold) > np.pi
    check_reach(hold)
    wide = hold.with_object(ObjectSpec.parse("circle:0.035", ROD_SCALE))
    assert 2.5 < cage_wrap(wide) < np.pi
    with pytest.raises(InvalidParameterError, match=r"cannot close on circle:0.035 from this base: its cage at rest wraps 2\.8"):
        check_reach(wide)
    check_reach(replace(wide, law="paper"))
