"""Grasp holding, beyond the paper (docs/holding.md): what a settled grasp resists.

* :mod:`.experiment` - one grasp loaded on the rod engine: released, probed for its stiffness K
  and ramped for its holding capacity (``contgrasp hold``; "What is measured");
* :mod:`.measure` - the wrench capacity Q_H of a contact before simulating (eqs. (M1)-(M4));
* :mod:`.ceiling` - the most any activation within the muscles' bound holds in a shape (M5);
* :mod:`.study` - Q1-Q3 and Q_H against the measured holding over a quality map's poses
  (``contgrasp holding-study``; "The study").

The holding *law* is :mod:`contgrasp_core.control.hold_law`.
"""

from contgrasp_core.holding.experiment import (
    Capacity,
    GraspFailure,
    HoldExperiment,
    HoldResult,
    HoldSettings,
    force_weighted_quality,
    friction_bound,
    measure_holding,
    wrench_directions,
)

__all__ = ["HoldSettings", "Capacity", "HoldResult", "HoldExperiment", "GraspFailure", "measure_holding",
           "wrench_directions", "force_weighted_quality", "friction_bound"]
