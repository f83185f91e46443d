"""The grasped object as a planar rigid body (beyond the paper: its Sec. V-C object is fixed).

The object keeps its boundary and moves rigidly: the displacement ``q = (dx, dy, dpsi)`` from the
start pose (the centroid's translation and a rotation about it) and its velocity, under
Newton-Euler in the plane (``m v' = F``, ``J omega' = tau``) with the rod's contact forces
(:mod:`contgrasp_core.rod.coupling`), an applied wrench and, in ``"spring"`` mode, a
spring-damper to the start pose. Modes ``"fixed"`` (the paper's; the engine's fixed-object path),
``"spring"``, ``"free"``; mass and inertia from an areal density or given. docs/rod.md, "A movable object".
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from contgrasp_core.arm import ArmShape
from contgrasp_core.boundary import Boundary
from contgrasp_core.errors import InvalidParameterError

__all__ = ["MODES", "ObjectDynamics", "RigidBody", "BodyState", "mass_properties", "rotation", "to_world",
           "to_object_frame", "shape_in_object_frame", "motion_summary"]

Array = NDArray[np.float64]

MODES = ("fixed", "spring", "free")
"""How the object moves: not at all, on a spring-damper to its start pose, or freely."""


def _triple(name: str, value: ArrayLike) -> tuple[float, float, float]:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"{name} must be three numbers (x, y, rotation), got {value!r}") from exc
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise InvalidParameterError(f"{name} must be three finite numbers >= 0 (x, y, rotation), got {value!r}")
    return float(a[0]), float(a[1]), float(a[2])


def mass_properties(boundary: Boundary, samples: int = 4096) -> tuple[float, Array, float]:
    """Area (m^2), centroid (2,) and polar second moment of area about the centroid (m^4) of the
    region the boundary encloses: Green's theorem on the polygon of ``samples``
    arclength-equispaced boundary points (error O(samples^-2); exact values for a circle:
    ``pi R^2``, its centre, ``pi R^4 / 2``)."""
    _, p = boundary.sample(int(samples))
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    cx = ((x + xn) * cross).sum() / (6.0 * area)
    cy = ((y + yn) * cross).sum() / (6.0 * area)
    jz = ((x * x + x * xn + xn * xn + y * y + y * yn + yn * yn) * cross).sum() / 12.0  # about the origin
    area = abs(area)
    jz = abs(jz) - area * (cx * cx + cy * cy)
    return float(area), np.array([cx, cy]), float(jz)


@dataclass(frozen=True)
class ObjectDynamics:
    """How the scenario's object moves (SI): ``mode`` (:data:`MODES`); ``areal_density`` (kg/m^2)
    gives mass and inertia from the enclosed area unless ``mass`` (kg) and ``inertia`` (kg m^2,
    about the centroid) are given; ``stiffness`` (N/m, N/m, N m/rad) and ``damping`` (N s/m,
    N s/m, N m s/rad) of the spring to the start pose, used in ``"spring"`` mode. The default
    (``"fixed"``) is the paper's immovable object."""

    mode: str = "fixed"
    areal_density: float = 10.0
    mass: float | None = None
    inertia: float | None = None
    stiffness: tuple[float, float, float] = (0.0, 0.0, 0.0)
    damping: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise InvalidParameterError(f"object mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        for name in ("areal_density", "mass", "inertia"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise InvalidParameterError(f"object {name} must be a finite number > 0, got {v!r}")
        object.__setattr__(self, "stiffness", _triple("object stiffness", self.stiffness))
        object.__setattr__(self, "damping", _triple("object damping", self.damping))

    def body(self, boundary: Boundary) -> RigidBody | None:
        """The rigid body of ``boundary`` (None when the object is fixed)."""
        if self.mode == "fixed":
            return None
        area, centroid, polar = mass_properties(boundary)
        mass = self.areal_density * area if self.mass is None else self.mass
        inertia = self.areal_density * polar if self.inertia is None else self.inertia
        spring = self.mode == "spring"
        return RigidBody(mass=mass, inertia=inertia, centroid=(float(centroid[0]), float(centroid[1])),
                         stiffness=self.stiffness if spring else (0.0, 0.0, 0.0),
                         damping=self.damping if spring else (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class RigidBody:
    """A movable object's inertia and support: ``mass`` (kg), ``inertia`` (kg m^2 about the
    centroid), ``centroid`` at the start pose (m), diagonal spring ``stiffness`` and ``damping``
    to the start pose (zero: free)."""

    mass: float
    inertia: float
    centroid: tuple[float, float]
    stiffness: tuple[float, float, float] = (0.0, 0.0, 0.0)
    damping: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mass_matrix: Array = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("mass", "inertia"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InvalidParameterError(f"object {name} must be finite and > 0, got {v!r}")
        c = np.asarray(self.centroid, dtype=float)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise InvalidParameterError(f"object centroid must be two finite numbers, got {self.centroid!r}")
        object.__setattr__(self, "stiffness", _triple("object stiffness", self.stiffness))
        object.__setattr__(self, "damping", _triple("object damping", self.damping))
        object.__setattr__(self, "mass_matrix", np.array([self.mass, self.mass, self.inertia]))

    def support_wrench(self, q: Array, v: Array) -> Array:
        """The spring-damper's wrench ``-K q - C v`` (3,)."""
        return -np.asarray(self.stiffness) * q - np.asarray(self.damping) * v

    def max_speed(self, state: BodyState, points: Array) -> float:
        """The largest speed of the object's material points at ``points`` (n, 2) (m/s): those
        within the arm's reach tell whether the grasp has settled."""
        rel = np.asarray(points) - np.asarray(self.centroid) - state.q[:2]
        vel = state.v[:2] + state.v[2] * np.stack([-rel[:, 1], rel[:, 0]], axis=1)
        return float(np.hypot(vel[:, 0], vel[:, 1]).max())

    def pose(self, q: Array) -> Array:
        """Centroid position and rotation from the start ``(x, y, dpsi)`` (3,)."""
        return np.array([self.centroid[0] + q[0], self.centroid[1] + q[1], q[2]])


@dataclass(frozen=True)
class BodyState:
    """The object's displacement from its start pose ``q = (dx, dy, dpsi)`` and velocity
    ``v = (vx, vy, omega)`` (m, rad, m/s, rad/s)."""

    q: Array
    v: Array

    @classmethod
    def rest(cls) -> BodyState:
        return cls(q=np.zeros(3), v=np.zeros(3))


def motion_summary(q: ArrayLike | None, v: ArrayLike | None) -> dict[str, dict[str, float] | None]:
    """A run summary's ``object_displacement`` (from ``q``) and ``object_velocity`` (from ``v``),
    each ``{x, y, angle}`` (m, rad; m/s, rad/s), or ``None`` for a fixed object (``q`` None or
    empty): the keys ``contgrasp simulate`` and the launcher's summary share."""
    def triple(a: ArrayLike | None) -> dict[str, float] | None:
        x = np.asarray(a if a is not None else (), dtype=float)
        return None if x.size == 0 else dict(zip(("x", "y", "angle"), x.tolist(), strict=True))

    return {"object_displacement": triple(q), "object_velocity": triple(v)}


def rotation(angle: float) -> Array:
    """The 2 x 2 rotation matrix ``R(angle)``."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def to_world(points: Array, q: Array, centroid: Array) -> Array:
    """Where object points given at the start pose (n, 2) are after the displacement ``q``."""
    return centroid + q[:2] + (np.asarray(points) - centroid) @ rotation(q[2]).T


def to_object_frame(points: Array, q: Array, centroid: Array) -> Array:
    """World points (n, 2) in the object's start-pose frame (the inverse of :func:`to_world`)."""
    return centroid + (np.asarray(points) - centroid - q[:2]) @ rotation(q[2])


def shape_in_object_frame(shape: ArmShape, q: Array, centroid: Array) -> ArmShape:
    """The arm moved with the inverse of the object's displacement: sensing it against the
    object's start-pose boundary gives the contact state against the moved object (rho, alpha
    of eq. (4) are invariant under a rigid motion of arm and object together)."""
    return ArmShape(s=shape.s, r=to_object_frame(shape.r, q, centroid), theta=np.asarray(shape.theta) - q[2])
