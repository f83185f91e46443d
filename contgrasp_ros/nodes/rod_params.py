"""Rod parameters shared by the simulator and the controller (they must describe the same rod)."""

from __future__ import annotations

from rclpy.node import Node

from contgrasp_core.rod.model import FRICTION_MODELS, RodModel
from contgrasp_core.scenario import PAPER
from contgrasp_ros.plumbing.parameters import declare

__all__ = ["declare_rod_model"]

_DEFAULTS = PAPER.rod  # a node started without a parameter file simulates the paper's arm


def declare_rod_model(node: Node) -> RodModel:
    """Declare the rod's geometry/material parameters (read-only) and build the model (SI).

    Invalid combinations raise InvalidParameterError, so the node refuses to start.
    """
    m = _DEFAULTS
    v = {
        "length": declare(node, "length", m.length, "arm length L [m]", lo=1e-6, hi=100.0, read_only=True),
        "n_elements": declare(node, "n_elements", m.n_elements, "rod elements N", lo=2, hi=100000, read_only=True),
        "radius_base": declare(node, "radius_base", m.radius_base, "radius at the base [m]", lo=1e-9, hi=10.0, read_only=True),
        "radius_tip": declare(node, "radius_tip", m.radius_tip, "radius at the tip [m]", lo=1e-9, hi=10.0, read_only=True),
        "density": declare(node, "density", m.density, "density [kg/m^3]", lo=1e-9, hi=1e6, read_only=True),
        "youngs_modulus": declare(node, "youngs_modulus", m.youngs_modulus, "Young's modulus E [Pa]", lo=1e-9, hi=1e13, read_only=True),
        "damping": declare(node, "damping", m.damping, "viscous damping zeta [1/s]", lo=0.0, hi=1e9, read_only=True),
        "drag_normal": declare(node, "drag_normal", m.drag_normal, "normal quadratic drag [kg/m^3]", lo=0.0, hi=1e9, read_only=True),
        "drag_tangential": declare(node, "drag_tangential", m.drag_tangential, "tangential quadratic drag [kg/m^3]", lo=0.0, hi=1e9, read_only=True),
        "contact_stiffness": declare(node, "contact_stiffness", m.contact_stiffness, "contact stiffness [N/m^2]", lo=0.0, hi=1e12, read_only=True),
        "contact_damping": declare(node, "contact_damping", m.contact_damping, "contact damping [N s/m^2]", lo=0.0, hi=1e12, read_only=True),
        "friction": declare(node, "friction", m.friction, "Coulomb friction coefficient", lo=0.0, hi=10.0, read_only=True),
        "friction_model": declare(node, "friction_model", m.friction_model,
                                  "friction law with friction > 0: regularised (smooth Coulomb) or stick (stick-slip)",
                                  read_only=True, choices=FRICTION_MODELS),
        "max_muscle_stress": declare(node, "max_muscle_stress", m.max_muscle_stress,
                                     "the muscles' largest stress, bounds each section's couple [Pa]; 0 = unbounded",
                                     lo=0.0, hi=1e9, read_only=True),
        "base_x": declare(node, "base_x", m.base_position[0], "base position x [m]", lo=-1e6, hi=1e6, read_only=True),
        "base_y": declare(node, "base_y", m.base_position[1], "base position y [m]", lo=-1e6, hi=1e6, read_only=True),
        "base_angle": declare(node, "base_angle", m.base_angle, "base heading theta0 [rad]", lo=-100.0, hi=100.0, read_only=True),
    }
    base = (v.pop("base_x"), v.pop("base_y"))
    return RodModel(base_position=base, **v)
