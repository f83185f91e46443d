"""The paper's dynamic grasp scenario (Sec. V-C and appendix D) as defaults.

Arm: L = 20 cm, radius 1 cm at the base to 0.1 cm at the tip (linear taper), base at the origin
with heading 0; object: circle of radius 2.5 cm centred 8 cm right of and 8 cm above the base;
octopus material and drag (density 1042 kg/m^3, E = 10 kPa, drag 5110 / 25.55). The damping
``zeta = 1 /s`` and the contact law are this project's choices (docs/rod.md).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from contgrasp_core.boundary import Boundary, circle
from contgrasp_core.rod.model import RodModel

__all__ = ["PAPER_OBJECT_RADIUS", "PAPER_OBJECT_CENTER", "paper_model", "paper_object"]

PAPER_OBJECT_RADIUS = 0.025
PAPER_OBJECT_CENTER = (0.08, 0.08)

_PAPER = RodModel(length=0.20, n_elements=100, radius_base=0.01, radius_tip=0.001, density=1042.0,
                  youngs_modulus=1.0e4, damping=1.0, drag_normal=5110.0, drag_tangential=25.55,
                  contact_stiffness=1.0e5, contact_damping=1.0)


def paper_model(n_elements: int = 100, **overrides: Any) -> RodModel:
    """The paper's arm as a :class:`RodModel` (any field can be overridden, with a value of its type)."""
    return replace(_PAPER, n_elements=n_elements, **overrides)


def paper_object() -> Boundary:
    """The paper's circular object."""
    return circle(PAPER_OBJECT_RADIUS, PAPER_OBJECT_CENTER)
