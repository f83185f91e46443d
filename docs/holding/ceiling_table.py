"""The muscles' ceiling (M5) of the holding law's rest on the paper's fixed circle, 10 kPa to unbounded,
and of the planned hold's rest at 50 kPa (docs/holding.md, "The muscles' ceiling", "Within the
muscles")."""

from dataclasses import replace
import numpy as np
from contgrasp_core.scenario import PAPER
from contgrasp_core.holding import wrench_directions
from contgrasp_core.holding.ceiling import muscle_ceiling
from contgrasp_core.holding.plan import plan_hold

s = replace(PAPER, law="hold")


def rest(rod):
    """The element angles of the planned hold's rest on the fixed circle, planned with ``rod``."""
    kappa = plan_hold(replace(s, rod=rod)).kappa[-1]
    return rod.base_angle + np.cumsum(kappa * rod.joint_len)


def ceiling(rod, theta, mu):
    """(M5) of the rod at rest in ``theta``, forces every 45 degrees from +x, then the two torques."""
    return muscle_ceiling(rod, s.object.boundary(), theta, mu=mu, directions=wrench_directions(8), ref=s.reference,
                          scale=s.object.radius, tol=5e-4)


theta = rest(s.rod)  # the holding law's rest on the fixed circle (unbounded muscles)
for stress in (1e4, 2e4, 5e4, 1e5, 0.0):
    for mu in (0.0, 0.5):
        c = ceiling(replace(s.rod, max_muscle_stress=stress), theta, mu)
        print(f"{stress:>8g} Pa  mu {mu}: holds the shape {c.holds_shape}, min {c.capacity.min():.3f} N,",
              np.round(c.capacity, 3))

# the planned hold's own rest at 50 kPa (its plan run with the bounded muscles): which joint binds
rod = replace(s.rod, max_muscle_stress=5e4)
theta = rest(rod)
headroom = 1.0 - np.abs(rod.joint_ei * rod.joint_curvature(theta)) / rod.muscle_bound
print(f"the 50 kPa plan's rest: the clamp's bend leaves {headroom[0]:.1%} of its muscle, the other joints "
      f"at least {headroom[1:].min():.0%}")
for mu in (0.5, 1.0, 2.0):
    c = ceiling(rod, theta, mu)
    print(f"   50000 Pa  mu {mu}: the 50 kPa plan's rest, holds the shape {c.holds_shape}, min {c.capacity.min():.3f} N,",
          np.round(c.capacity, 3))
