"""Friction that holds (contgrasp_core.rod.coupling, stick-slip): the capstan law at the
Coulomb limit and no creep below it, against the regularised model's creep.

The set-up: a uniform rod (r = 3 mm) clamped at the origin runs straight, then wraps half-way
(phi = pi) around a circle of radius R = 3 cm whose centre is at the rod's centreline radius
R + r above it; the joint couples cancel the wrap's bending moment (``u = -EI / (R + r)``), so
the wrapped rod carries tension like a rope. The tip is pulled on along its tangent with T2.
The circle is held in translation by a stiff spring and free to turn; a torque tau on it drags
the rod towards its tip against the clamp. A rope on a drum slips when the tension before the
wrap reaches ``T1 = T2 exp(mu phi)`` (the capstan law), i.e. at ``tau = (R + r) T2 (exp(mu
phi) - 1)`` (the friction acts at the rod's centreline in the model).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import pytest

from contgrasp_core.boundary import circle
from contgrasp_core.rod import RodLoads, RodModel, RodState, RodSystem
from contgrasp_core.rod.body import BodyState, RigidBody
from contgrasp_core.rod.obstacle import Obstacle

R, r, T2, PHI = 0.03, 0.003, 0.05, np.pi


def capstan_limit(mu: float) -> float:
    return (R + r) * T2 * (np.exp(mu * PHI) - 1.0)


def wrapped_drum(friction_model: str, mu: float, torque: Callable[[float], float], duration: float,
                 settle: float = 0.3, dt: float = 1e-3) -> np.ndarray:
    """Rows (t, torque, drum angle, drum rate) every step of the set-up in the module docstring;
    the torque starts after ``settle`` s."""
    length, n = 0.2, 60
    straight = length - PHI * (R + r)
    model = RodModel(length=length, n_elements=n, radius_base=r, radius_tip=r, damping=5.0, contact_stiffness=1e5,
                     contact_damping=1.0, friction=mu, friction_model=friction_model)
    centre = (straight, R + r)
    body = RigidBody(mass=0.02, inertia=1e-5, centroid=centre, stiffness=(1e3, 1e3, 0.0), damping=(1.0, 1.0, 0.0))
    system = RodSystem(model, Obstacle(circle(R, centre)), body=body)
    theta = np.maximum(model.s_centres - straight, 0.0) / (R + r)
    couple = np.where(model.joint_s > straight, -model.joint_ei / (R + r), 0.0)
    pull = np.zeros((n + 1, 2))
    pull[-1] = T2 * np.array([np.cos(theta[-1]), np.sin(theta[-1])])
    state = RodState(0.0, theta, np.zeros(n), BodyState.rest())
    rows = []
    while state.t < duration - 1e-12:
        tau = 0.0 if state.t < settle else torque(state.t - settle)
        state, _ = system.advance(state, dt, RodLoads(couple=couple, node_forces=pull, wrench=np.array([0.0, 0.0, tau])))
        assert state.body is not None
        rows.append((state.t, tau, state.body.q[2], state.body.v[2]))
    return np.array(rows)


@pytest.mark.heavy
@pytest.mark.parametrize("mu", [0.15, 0.5])
def test_stick_slip_slips_at_the_capstan_limit(mu: float) -> None:
    """A slowly rising torque: the drum starts to turn (rate above 0.05 rad/s, against ~4e-3
    rad/s of elastic give before) within 5 % of the capstan law's torque."""
    limit = capstan_limit(mu)
    rows = wrapped_drum("stick", mu, lambda t: limit * t, duration=1.5)
    loaded = rows[rows[:, 0] > 0.35]
    slipping = np.abs(loaded[:, 3]) > 0.05
    assert slipping.any()
    tau_slip = loaded[np.argmax(slipping), 1]
    assert abs(tau_slip / limit - 1.0) < 0.05, (tau_slip, limit)


@pytest.mark.heavy
def test_stick_slip_holds_below_the_limit_where_regularised_friction_creeps() -> None:
    """A steady torque at 60 % of the capstan limit, held for 2 s: with stick-slip friction the
    drum's rate over the last second is below 1e-6 rad/s (measured ~1e-10); the regularised
    model (``mu f_n tanh(v_t / 1 mm/s)``) lets it creep at ~0.027 rad/s (0.9 mm/s at the surface)."""
    tau = 0.6 * capstan_limit(0.3)
    rates = {}
    for model in ("stick", "regularised"):
        rows = wrapped_drum(model, 0.3, lambda t: tau, duration=2.3)
        late = rows[rows[:, 0] > 1.3]
        rates[model] = abs(np.polyfit(late[:, 0], late[:, 2], 1)[0])
    assert rates["stick"] < 1e-6, rates
    assert rates["regularised"] > 1e-2, rates


def test_stick_slip_away_from_the_object_is_the_frictionless_rod() -> None:
    """Before it touches anything, a rod with stick-slip friction moves exactly as one without
    friction (no contact frame, no anchors needed)."""
    from dataclasses import replace

    model = RodModel(n_elements=12, damping=1.0)
    far = Obstacle(circle(0.02, (0.5, 0.5)))
    couple = np.full(12, 1e-6)
    runs = []
    for m in (model, replace(model, friction=0.5, friction_model="stick")):
        system = RodSystem(m, far)
        state, _ = system.advance(system.straight_state(), 0.05, RodLoads(couple=couple), dt_try=0.005)
        runs.append(state.theta)
    np.testing.assert_array_equal(runs[0], runs[1])
