"""Whether a run stayed where the rod model holds, and what it asked of the muscles (docs/rod.md, "Validity").

The penalty contact and the sensing of (rho, alpha) (paper eqs. (4), (5)) describe a surface
pressed in by a small fraction of its radius. :class:`RunHealth` follows a run's states and
applied couples: a run whose arm went deeper into the object than :data:`PENETRATION_LIMIT` of
the local radius, or into itself deeper than :data:`SELF_OVERLAP_LIMIT` of the thinner part's
radius, left the model and is never reported as settled; and the largest couple applied, where,
and its ratio to the muscles' bound (:attr:`RodModel.muscle_bound`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.rod.model import RodModel
from contgrasp_core.rod.self_contact import self_gap

__all__ = ["PENETRATION_LIMIT", "SELF_OVERLAP_LIMIT", "RunHealth"]

Array = NDArray[np.float64]

PENETRATION_LIMIT = 0.3
"""The deepest penetration into the object, as a fraction of the local radius, of a valid run."""

SELF_OVERLAP_LIMIT = 0.3
"""The deepest overlap of the arm with itself, as a fraction of the thinner part's radius, of a valid run."""


@dataclass
class RunHealth:
    """The model's validity and the muscles' effort over a run (module docstring), fed in time order."""

    model: RodModel
    penetration_ratio: float = 0.0
    penetration_at: tuple[float, float] = (np.nan, np.nan)  # (t, s)
    self_overlap_ratio: float = 0.0
    self_overlap_at: tuple[float, float, float] = (np.nan, np.nan, np.nan)  # (t, s, s of the other part)
    peak_couple: float = 0.0
    peak_couple_at: tuple[float, float] = (np.nan, np.nan)  # (t, s)
    _bound_at_peak: float = field(default=np.nan, repr=False)

    def observe(self, t: float, theta: Array, ratio: Array, s: Array) -> None:
        """The state at time ``t`` (element angles ``theta``) with the penetration into the object
        over the local radius ``ratio`` at arclengths ``s`` (the points the caller projected)."""
        k = int(np.argmax(ratio))
        if ratio[k] > self.penetration_ratio:
            self.penetration_ratio, self.penetration_at = float(ratio[k]), (float(t), float(s[k]))
        gap = self_gap(self.model, theta, margin=0.0)
        if gap.ratio > self.self_overlap_ratio:
            self.self_overlap_ratio, self.self_overlap_at = gap.ratio, (float(t), gap.s, gap.s_other)

    def applied(self, t: float, couple: Array) -> None:
        """The couple (N,) applied at the joints from time ``t`` (after the muscles' saturation)."""
        k = int(np.argmax(np.abs(couple)))
        if abs(couple[k]) > self.peak_couple:
            self.peak_couple, self.peak_couple_at = float(abs(couple[k])), (float(t), float(self.model.joint_s[k]))
            bound = self.model.muscle_bound
            self._bound_at_peak = np.nan if bound is None else float(bound[k])

    @property
    def valid(self) -> bool:
        return self.penetration_ratio <= PENETRATION_LIMIT and self.self_overlap_ratio <= SELF_OVERLAP_LIMIT

    def broken(self) -> list[str]:
        """One sentence per limit the run broke (empty: valid)."""
        out = []
        if self.penetration_ratio > PENETRATION_LIMIT:
            t, s = self.penetration_at
            out.append(f"the arm went {self.penetration_ratio:.2f} of its radius into the object at s = {s:.4g} m "
                       f"(t = {t:.4g} s; the model holds to {PENETRATION_LIMIT})")
        if self.self_overlap_ratio > SELF_OVERLAP_LIMIT:
            t, s, other = self.self_overlap_at
            out.append(f"the arm passed {self.self_overlap_ratio:.2f} of its radius through itself at s = {s:.4g} m "
                       f"and s = {other:.4g} m (t = {t:.4g} s; the model holds to {SELF_OVERLAP_LIMIT})")
        return out

    def validity(self) -> dict[str, Any]:
        """The JSON ``validity`` block: ``valid``, what broke (``broken``, sentences) and the measures."""
        return {"valid": self.valid, "broken": self.broken(),
                "max_penetration_ratio": self.penetration_ratio, "penetration_limit": PENETRATION_LIMIT,
                "max_self_overlap_ratio": self.self_overlap_ratio, "self_overlap_limit": SELF_OVERLAP_LIMIT}

    def effort(self) -> dict[str, Any]:
        """``peak_couple`` (N m, the largest |u| applied), ``peak_couple_arclength`` (m, its joint),
        ``peak_couple_sim_time_s`` (s) and ``peak_couple_ratio`` (that couple over the muscles' bound at its
        joint; None when the muscles are unbounded)."""
        ratio = None if np.isnan(self._bound_at_peak) else self.peak_couple / self._bound_at_peak
        return {"peak_couple": self.peak_couple, "peak_couple_arclength": _plain(self.peak_couple_at[1]),
                "peak_couple_sim_time_s": _plain(self.peak_couple_at[0]), "peak_couple_ratio": ratio}


def _plain(v: float) -> float | None:
    return None if np.isnan(v) else float(v)
