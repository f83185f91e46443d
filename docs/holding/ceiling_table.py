"""The muscles' ceiling (M5) of the holding law's rest on the paper's fixed circle, 10 kPa to unbounded
(docs/holding.md, "The muscles' ceiling")."""

from dataclasses import replace
import numpy as np
from contgrasp_core.scenario import PAPER
from contgrasp_core.holding import wrench_directions
from contgrasp_core.holding.ceiling import muscle_ceiling
from contgrasp_core.holding.plan import plan_hold

s = replace(PAPER, law="hold")
kappa = plan_hold(s).kappa[-1]  # the holding law's rest on the fixed circle (unbounded muscles)
theta = s.rod.base_angle + np.cumsum(kappa * s.rod.joint_len)
for stress in (1e4, 2e4, 5e4, 1e5, 0.0):
    for mu in (0.0, 0.5):
        c = muscle_ceiling(replace(s.rod, max_muscle_stress=stress), s.object.boundary(), theta, mu=mu,
                           directions=wrench_directions(8), ref=s.reference, scale=s.object.radius, tol=5e-4)
        print(f"{stress:>8g} Pa  mu {mu}: holds the shape {c.holds_shape}, min {c.capacity.min():.3f} N,",
              np.round(c.capacity, 3))
