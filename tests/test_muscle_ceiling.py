"""The muscles' ceiling (M5, holding/ceiling.py) against statics worked by hand."""

import numpy as np
import pytest

from contgrasp_core.boundary import circle
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.holding.ceiling import joint_moments, muscle_ceiling
from contgrasp_core.rod import RodModel, chain

ROD = RodModel(n_elements=40, max_muscle_stress=5.0e4)
UP = np.array([[0.0, 1.0, 0.0]])  # (the load pushing the object into the arm from below)


def _touching_below(rod: RodModel, j: int, radius: float = 0.004):
    """A straight arm along +x and a circle below it whose top touches element ``j``'s surface."""
    xc = (j + 0.5) * rod.h
    centre = (xc, -(radius + rod.r_centres[j]))
    return np.zeros(rod.n_elements), circle(radius, centre), centre


def test_joint_moments_are_the_cross_products_about_each_joint():
    rng = np.random.default_rng(3)
    theta = np.cumsum(rng.normal(0.0, 0.1, ROD.n_elements))
    f = rng.normal(0.0, 1.0, (ROD.n_elements, 2))
    nodes, centres = chain.nodes(ROD, theta), chain.centres(ROD, theta)
    lever = centres[None, :, :] - nodes[:-1, None, :]  # (joint k, element m, 2)
    cross = lever[..., 0] * f[None, :, 1] - lever[..., 1] * f[None, :, 0]
    expected = np.array([cross[k, k:].sum() for k in range(ROD.n_elements)])
    np.testing.assert_allclose(joint_moments(ROD, theta, f), expected, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_one_contact_push_is_the_weakest_joints_bound_over_its_lever(mu):
    j = 25
    theta, obj, centre = _touching_below(ROD, j)
    ceiling = muscle_ceiling(ROD, obj, theta, mu=mu, directions=UP, ref=centre, scale=0.004, tol=1e-6)
    assert ceiling.contacts == 1 and ceiling.holds_shape
    k = np.arange(j + 1)
    per_joint = ROD.muscle_bound[: j + 1] / ((j + 0.5 - k) * ROD.h)  # (the straight arm: no elastic couple)
    assert ceiling.capacity[0] == pytest.approx(per_joint.min(), rel=1e-9)
    assert ceiling.binding[0] == np.argmin(per_joint)  # (joint 16 here: the taper against the lever)


def test_an_arm_cannot_pull_and_unbounded_muscles_push_without_limit():
    j = 25
    theta, obj, centre = _touching_below(ROD, j)
    pull = muscle_ceiling(ROD, obj, theta, mu=0.0, directions=-UP, ref=centre, scale=0.004, tol=1e-6)
    assert pull.capacity[0] == 0.0
    free = RodModel(n_elements=40)
    push = muscle_ceiling(free, obj, theta, mu=0.0, directions=UP, ref=centre, scale=0.004, tol=1e-6)
    assert push.capacity[0] == np.inf and push.binding[0] == -1


def test_frictionless_contact_on_a_circle_holds_no_torque_about_its_centre():
    j = 25
    theta, obj, centre = _touching_below(ROD, j)
    torque = muscle_ceiling(RodModel(n_elements=40), obj, theta, mu=0.0, directions=[[0, 0, 1.0], [0, 0, -1.0]],
                            ref=centre, scale=0.004, tol=1e-6)
    np.testing.assert_array_equal(torque.capacity, [0.0, 0.0])


def test_a_shape_the_muscles_cannot_hold_holds_nothing():
    theta = np.full(ROD.n_elements, 1.5)  # (a 1.5 rad kink at the clamp: EI_0 kappa_0 beyond the base's bound)
    assert ROD.joint_ei[0] * ROD.joint_curvature(theta)[0] > ROD.muscle_bound[0]
    far = circle(0.01, (1.0, 1.0))
    ceiling = muscle_ceiling(ROD, far, theta, mu=0.5, directions=UP, ref=(1.0, 1.0), scale=0.01, tol=5e-4)
    assert not ceiling.holds_shape and ceiling.capacity[0] == 0.0 and ceiling.contacts == 0


def test_bad_input_is_refused():
    theta, obj, centre = _touching_below(ROD, 10)
    with pytest.raises(InvalidParameterError, match="element angles"):
        muscle_ceiling(ROD, obj, theta[:-1], mu=0.0, directions=UP, ref=centre, scale=0.004, tol=0.0)
    with pytest.raises(InvalidParameterError, match="load directions"):
        muscle_ceiling(ROD, obj, theta, mu=0.0, directions=[[1.0, 0.0]], ref=centre, scale=0.004, tol=0.0)
    with pytest.raises(InvalidParameterError, match="tolerance"):
        muscle_ceiling(ROD, obj, theta, mu=0.0, directions=UP, ref=centre, scale=0.004, tol=-1.0)
