"""The rod's closed loop linearised about a rest (contgrasp_core.control.rod_feedback.rest_stability;
docs/holding.md, "The cage flutters") against independent truth: the closed form of a damped
elastic rod and of the hold (H4), a potential (every mode decays at half the damping); the cage's
rest (H1) grows at the rate the rod engine's own integration of a tiny perturbation shows, and
that rate converges as the rod is refined (a property of the continuum, not of the grid)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contgrasp_core.control.hold_law import HoldController, ShapeHold, cage_gains
from contgrasp_core.control.rod_feedback import StateFeedback, rest_shape, rest_stability
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import Obstacle, RodSystem
from contgrasp_core.rod.integrator import RodLoads, RodState, StepOptions
from contgrasp_core.rod.model import RodModel
from contgrasp_core.scenario import PAPER

BASE = (0.12, 0.08, np.pi / 2)  # (the circle study's first grid pose, docs/holding/circle_hold_dwell.jsonl)
OBSTACLE = Obstacle(PAPER.object.boundary())


def _cage(n: int) -> tuple[RodModel, StateFeedback, np.ndarray]:
    """The rod of ``n`` elements at ``BASE``, the cage's law at its close gap, and its rest."""
    sc = PAPER.with_object(PAPER.object, rod=replace(PAPER.rod, n_elements=n, base_position=BASE[:2],
                                                     base_angle=BASE[2]), law="reactive")
    law = sc.controller()
    assert isinstance(law, HoldController)
    gains = cage_gains(sc.rod, law.object_radius, law.settings, law.settings.close_gap, law.length_unit)
    return sc.rod, StateFeedback(sc.rod, OBSTACLE, gains), rest_shape(sc.rod, OBSTACLE, gains)


@pytest.mark.parametrize("gain", [0.0, 3000.0])
def test_the_bare_rod_and_the_hold_decay_at_half_the_damping(gain: float) -> None:
    """With no feedback (gain 0) or the hold (H4) ``G EI (kappa - kappa_ref)``, a potential, the
    linearised loop is ``M d'' + zeta M d' + K' d = 0`` with ``K'`` symmetric positive definite:
    every mode ``s = -zeta/2 +- i sqrt(omega^2 - zeta^2/4)`` (all under-damped at zeta = 0.2/s),
    so every real part is -zeta/2, whatever the shape."""
    rod, _, theta = _cage(40)
    damped = replace(rod, damping=0.2)
    st = rest_stability(damped, ShapeHold(damped, damped.joint_curvature(theta), gain), theta)
    assert st.exponents.shape == (80,)
    np.testing.assert_allclose(st.exponents.real, -0.1, rtol=1e-7)
    assert st.growth_rate == pytest.approx(-0.1, rel=1e-7) and st.frequency > 0.0


def test_the_cage_flutters_at_the_rate_the_rod_engine_integrates() -> None:
    """The cage (H1) at its rest on the circle: one mode pair grows (Prop. 5.2 assumes a
    gradient law; eq. (19) is not one), at ~17/s and ~58 rad/s. The rod engine (implicit
    midpoint, no numerical damping, the drag and the sensing as in every run), started 1e-9 rad
    off the rest, grows at that rate: the log of the amplitude's per-period peaks over the last
    half of 0.8 s (amplitude still below 1e-2 rad) has its slope within 2 %."""
    rod, feedback, theta = _cage(30)
    st = rest_stability(rod, feedback, theta)
    assert int((st.exponents.real > 0).sum()) == 2  # (one oscillating pair)
    assert 10.0 < st.growth_rate < 25.0 and 40.0 < st.frequency < 80.0
    system = RodSystem(rod, OBSTACLE, StepOptions(method="midpoint"))
    state = RodState(0.0, theta + 1e-9 * np.random.default_rng(1).standard_normal(len(theta)), np.zeros(len(theta)))
    dt, loads = 2e-4, RodLoads(feedback=feedback)
    amplitude = []
    for _ in range(4000):
        state, _ = system.step(state, dt, loads)
        amplitude.append(np.abs(state.theta - theta).max())
    a, t = np.array(amplitude), dt * np.arange(1, len(amplitude) + 1)
    w = int(round(2 * np.pi / st.frequency / dt))
    windows = range(0, len(a) - w + 1, w)
    peaks = np.array([a[i:i + w].max() for i in windows])
    times = np.array([t[i + int(np.argmax(a[i:i + w]))] for i in windows])
    assert peaks[-1] < 1e-2 and peaks[-1] > 1e3 * peaks[0]
    half = len(peaks) // 2
    slope = np.polyfit(times[half:], np.log(peaks[half:]), 1)[0]
    assert slope == pytest.approx(st.growth_rate, rel=0.02)


def test_the_cages_growth_rate_converges_as_the_rod_is_refined() -> None:
    """50, 100 and 200 elements: the growing mode's rate and frequency change by less than
    2 % per halving of the element, and less at the second (the continuum's flutter)."""
    modes = []
    for n in (50, 100, 200):
        rod, feedback, theta = _cage(n)
        st = rest_stability(rod, feedback, theta)
        modes.append((st.growth_rate, st.frequency))
    (g1, f1), (g2, f2), (g3, f3) = modes
    assert abs(g2 - g1) < 0.02 * g1 and abs(f2 - f1) < 0.02 * f1
    assert abs(g3 - g2) < abs(g2 - g1) and abs(f3 - f2) < abs(f2 - f1)


def test_a_bad_shape_is_refused() -> None:
    rod, feedback, theta = _cage(30)
    with pytest.raises(InvalidParameterError, match="30 finite element angles"):
        rest_stability(rod, feedback, theta[:-1])
    with pytest.raises(InvalidParameterError, match="30 finite element angles"):
        rest_stability(rod, feedback, np.where(np.arange(30) == 3, np.nan, theta))
