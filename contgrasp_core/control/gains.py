"""Gains of the feedback law at the rod joints (paper Sec. V-B, eq. (19); Appendix IV)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contgrasp_core.control.law import CENTIMETRE, adaptive_mu2
from contgrasp_core.rod.model import RodModel

__all__ = ["FeedbackGains", "paper_gains"]


@dataclass(frozen=True)
class FeedbackGains:
    """Gains of eq. (19) at the rod joints: ``mu1`` (scalar or (N,)), ``mu2`` (scalar
    or (N,), law units) and ``length_unit`` (metres per law unit, cm by default)."""

    mu1: float | np.ndarray = 1.0
    mu2: float | np.ndarray = 0.0
    length_unit: float = CENTIMETRE


def paper_gains(model: RodModel, object_radius: float, *, mu1: float = 1.0,
                length_unit: float = CENTIMETRE) -> FeedbackGains:
    """``mu1 = 1`` and the adaptive ``mu2(s) = r(s) - 1/(r_obj + r(s))`` (Appendix IV) at the joints."""
    return FeedbackGains(mu1=mu1, mu2=adaptive_mu2(model.radius(model.joint_s), object_radius,
                                                   length_unit=length_unit), length_unit=length_unit)
