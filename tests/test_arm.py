"""Arm shape from curvature against closed forms (arc, clothoid) and its convergence order."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import fresnel

from contgrasp_core.arm import Arm, BasePose, curvature_spline, shape_from_curvature
from contgrasp_core.errors import InvalidParameterError


def test_constant_curvature_is_a_circular_arc() -> None:
    k, th0 = 0.7, 0.4
    base = BasePose(1.0, -2.0, th0)
    s = np.linspace(0, 6.0, 31)
    shape = shape_from_curvature(s, np.full_like(s, k), base)
    np.testing.assert_allclose(shape.theta, th0 + k * s, atol=1e-13)
    x = 1.0 + (np.sin(th0 + k * s) - np.sin(th0)) / k
    y = -2.0 - (np.cos(th0 + k * s) - np.cos(th0)) / k
    np.testing.assert_allclose(shape.r, np.stack([x, y], -1), atol=1e-12)


def test_linear_curvature_is_a_clothoid() -> None:
    c = 0.3
    s = np.linspace(0, 5.0, 201)
    shape = shape_from_curvature(s, c * s)
    scale = np.sqrt(np.pi / c)
    S, C = fresnel(s / scale)  # scipy returns (S, C) with the pi t^2 / 2 convention
    np.testing.assert_allclose(shape.r[:, 0], scale * C, atol=1e-11)
    np.testing.assert_allclose(shape.r[:, 1], scale * S, atol=1e-11)


def test_fourth_order_convergence() -> None:
    """Error against an independent high-accuracy ODE solution drops ~16x per halving."""
    L = 8.0

    def kappa(s):  # type: ignore[no-untyped-def]
        return 0.4 * np.sin(1.3 * s) + 0.1

    errs = []
    for n in (81, 161, 321):
        s = np.linspace(0, L, n)
        ref = solve_ivp(
            lambda s, y: [np.cos(y[2]), np.sin(y[2]), kappa(s)],
            (0, L),
            [0, 0, 0],
            t_eval=s,
            rtol=1e-13,
            atol=1e-14,
            method="DOP853",
        )
        shape = shape_from_curvature(s, kappa(s))
        errs.append(max(np.max(np.abs(shape.r - ref.y[:2].T)), np.max(np.abs(shape.theta - ref.y[2]))))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 3.5), orders


def test_radius_profiles_and_validation() -> None:
    arm = Arm.paper_tapered(20.0)
    assert arm.radius(0.0) == pytest.approx(1.0)
    assert arm.radius(20.0) == pytest.approx(0.1)
    assert Arm(3.0, 0.5).radius(np.array([0.0, 3.0])).tolist() == [0.5, 0.5]
    with pytest.raises(InvalidParameterError):
        Arm(-1.0, 0.1)
    with pytest.raises(InvalidParameterError):
        Arm(1.0, 0.1, radius_tip=0.0)
    with pytest.raises(InvalidParameterError):
        shape_from_curvature([0.0, 1.0, 0.5], [0.0, 0.0, 0.0])
    with pytest.raises(InvalidParameterError):
        shape_from_curvature([0.0, 1.0, 2.0], [0.0, 0.0])
    with pytest.raises(InvalidParameterError):
        shape_from_curvature([0.0, 1.0, 2.0], [0.0, np.nan, 0.0])
    with pytest.raises(InvalidParameterError):
        BasePose(np.inf, 0.0, 0.0)
    with pytest.raises(InvalidParameterError):
        arm.grid(1)


@pytest.mark.parametrize(("s", "kappa"), [
    ([-1.0, 0.0, 1e300], [0.0, 0.0, 0.0]),  # a span whose square overflows
    ([-1.0, 0.0, 5.5e-168], [0.0, 0.0, 1e300]),  # a slope that overflows
    ([-8.5e-24, 0.0, 1e300], [0.0, 1.0, 0.0]),
])
def test_curvature_samples_whose_spline_overflows_are_refused(s: list[float], kappa: list[float]) -> None:
    """Finite, increasing, but beyond what a cubic spline can hold in float64 (found by the
    entry-point fuzz test): a clear InvalidParameterError, not an overflow warning or scipy's
    ValueError; ordinary grids still work."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(InvalidParameterError, match="too extreme"):
            curvature_spline(s, kappa)
    assert np.all(np.isfinite(curvature_spline([0.0, 0.1, 0.2], [1.0, 2.0, 1.0]).c))
