"""How well the arm tracks the grasp targets over its contact set (paper eqs. (4), (5), Sec. V-C).

One contact state gives one set of statistics, over the nodes in contact (``in_contact``, paper
Definition 1 with the run's single contact tolerance, :class:`contgrasp_core.scenario.SensingSettings`):
how many nodes, the contact length ``int_S ds`` (the same quadrature as the grasp quality's
contact length, :func:`contgrasp_core.quality.contact_weights`), and the mean and the maximum of
the tracking errors ``|rho / rho_d - 1|`` (rho_d = r(s) = delta + rho, eq. (5)) and
``|alpha - pi/2|``. ``contgrasp simulate``, the launcher's summary and ``contgrasp analyze`` all
report these, so a statistic never leaves out which contact set it covers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from contgrasp_core.quality import contact_weights

__all__ = ["ContactStats", "contact_stats"]

FloatSeq = Sequence[float] | np.ndarray


@dataclass(frozen=True)
class ContactStats:
    """Tracking statistics over the ``contact_nodes`` nodes in contact of one contact state
    (``contact_length`` m long): mean and max of |rho / rho_d - 1| and of |alpha - pi/2|.
    The means and maxima are ``None`` without contact; ``contact_nodes`` and ``contact_length``
    are ``None`` without a contact state."""

    mean_abs_rho_ratio_minus_1_contact: float | None = None
    max_abs_rho_ratio_minus_1_contact: float | None = None
    mean_abs_alpha_minus_half_pi_contact: float | None = None
    max_abs_alpha_minus_half_pi_contact: float | None = None
    contact_nodes: int | None = None
    contact_length: float | None = None


def contact_stats(s: FloatSeq | None, rho: FloatSeq | None = None, delta: FloatSeq | None = None,
                  alpha: FloatSeq | None = None, in_contact: Sequence[bool] | np.ndarray | None = None,
                  tol: float = 0.0) -> ContactStats:
    """:class:`ContactStats` of one contact state given as per-node arrays on the arm grid ``s``
    with its contact flags and the tolerance ``tol`` (m) that made them (``s`` None: no contact
    state). The contact length integrates ``{delta >= -tol}`` like the quality evaluator."""
    if s is None or rho is None or delta is None or alpha is None or in_contact is None:
        return ContactStats()
    r = np.asarray(rho, dtype=float)
    d = np.asarray(delta, dtype=float)
    radius = d + r
    mask = np.asarray(in_contact, dtype=bool)
    n = int(np.count_nonzero(mask))
    length = float(contact_weights(np.asarray(s, dtype=float), d, float(tol)).sum()) if len(r) >= 2 else 0.0
    if n == 0:
        return ContactStats(contact_nodes=0, contact_length=length)
    e_rho = np.abs(r[mask] / radius[mask] - 1.0)
    e_alpha = np.abs(np.asarray(alpha, dtype=float)[mask] - np.pi / 2)
    return ContactStats(
        mean_abs_rho_ratio_minus_1_contact=float(np.mean(e_rho)),
        max_abs_rho_ratio_minus_1_contact=float(np.max(e_rho)),
        mean_abs_alpha_minus_half_pi_contact=float(np.mean(e_alpha)),
        max_abs_alpha_minus_half_pi_contact=float(np.max(e_alpha)),
        contact_nodes=n,
        contact_length=length,
    )
