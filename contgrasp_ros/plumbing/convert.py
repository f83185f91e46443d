"""Conversions between contgrasp_msgs messages and the core library's arrays.

Every ``*_arrays`` function validates what it receives (array lengths, finiteness, magnitudes,
sizes, a strictly increasing arclength grid) and raises :class:`MessageError` with the reason, so
nodes can drop a malformed message, count it under ``MessageError.reason`` and keep running.
The readers only use attribute access, so they work as well on messages decoded from a
recording without ROS (``mcap_ros2`` / ``rosbags`` objects); the message classes are imported
only by the ``*_to_msg`` builders. This module therefore imports without a ROS installation
(offline analysis, ``contgrasp analyze``).
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.arm import ArmShape
from contgrasp_core.boundary import Boundary, from_points
from contgrasp_core.contact import ContactState
from contgrasp_core.errors import ContgraspError, InputError
from contgrasp_core.rod.body import shape_in_object_frame
from contgrasp_core.quality import GraspQuality
from contgrasp_core.objects import ObjectSpec
from contgrasp_core.control import FeedbackExpansion
from contgrasp_core.control.hold_law import ShapeHold

if TYPE_CHECKING:
    from contgrasp_msgs.msg import ContactState as ContactStateMsg
    from contgrasp_msgs.msg import CoupleControl, ObjectBoundary
    from contgrasp_msgs.msg import GraspQuality as GraspQualityMsg
    from contgrasp_msgs.msg import RodState as RodStateMsg
    from contgrasp_core.rod.body import BodyState
    from contgrasp_core.rod.session import Observation
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import Header

__all__ = [
    "MessageError",
    "RodArrays",
    "ObjectArrays",
    "rod_state_arrays",
    "object_fields",
    "rod_state_fields",
    "wrench_arrays",
    "contact_fields",
    "contact_to_msg",
    "ContactArrays",
    "contact_arrays",
    "couple_fields",
    "couple_to_msg",
    "couple_arrays",
    "HeldShape",
    "quality_to_msg",
    "boundary_to_msg",
    "boundary_from_msg",
    "stamp_seconds",
    "float64_field",
    "require_finite",
    "MAX_SAMPLES",
    "MAX_ABS",
]

Array = NDArray[np.float64]


# Limits of what a message may carry. MAX_SAMPLES matches the largest rod the nodes accept
# (n_elements <= 100000, see nodes/rod_params.py); MAX_ABS bounds geometric values (m, rad):
# larger ones are absurd for an arm and overflow the sensing's squares.
MAX_SAMPLES = 100_001
MAX_ABS = 1e6


class MessageError(InputError):
    """A received message is malformed (wrong lengths, NaN/Inf, empty, bad grid, bad object).

    ``reason`` is a short category (``"length mismatch"``, ``"NaN/Inf"``, ...) that nodes use as
    the drop counter's key; the message text has the details.
    """

    def __init__(self, message: str, *, reason: str = "malformed") -> None:
        super().__init__(message)
        self.reason = reason


def stamp_seconds(header: Header) -> float:
    """Header stamp as float seconds."""
    return header.stamp.sec + 1e-9 * header.stamp.nanosec


def float64_field(values: object) -> array[float]:
    """A float64[] message field straight from an array's bytes: the generated message classes
    keep an ``array('d')`` as it is, whereas a list is checked value by value in Python (about
    4 us per 100 values; benchmarks/RESULTS.md, ros_loop)."""
    out = array("d")
    out.frombytes(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return out


def require_finite(what: str, *arrays: object) -> None:
    """Raise :class:`MessageError` (reason ``"non-finite result"``) unless every value is finite:
    a node checks what it computed from a valid but extreme message before publishing it."""
    values = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in arrays])  # (one check for all)
    if not np.isfinite(values).all():
        raise MessageError(f"{what} is not finite (NaN/Inf)", reason="non-finite result")


def _arrays(msg: object, names: tuple[str, ...], *, min_len: int = 2, max_abs: float | None = MAX_ABS) -> dict[str, Array]:
    kind = type(msg).__name__
    fields = [getattr(msg, name) for name in names]
    n = len(fields[0])
    if n < min_len:
        raise MessageError(f"{kind}: needs at least {min_len} samples, got {n}", reason="too few samples")
    if n > MAX_SAMPLES:
        raise MessageError(f"{kind}: {n} samples, at most {MAX_SAMPLES} accepted", reason="too many samples")
    for name, field in zip(names, fields, strict=True):
        if len(field) != n:
            raise MessageError(f"{kind}: field '{name}' has {len(field)} samples, '{names[0]}' has {n}",
                               reason="length mismatch")
    # one block (a copy: writable whatever the fields are - numba compiles read-only arrays as
    # another signature) and one comparison for all fields (NaN and Inf fail it too); the first
    # bad field is named
    block = np.array(fields, dtype=float).reshape(len(names), n)
    ok = np.isfinite(block) if max_abs is None else np.abs(block) <= max_abs
    if not ok.all():
        i = int(np.flatnonzero(~ok.all(axis=1))[0])
        if not np.all(np.isfinite(block[i])):
            raise MessageError(f"{kind}: field '{names[i]}' contains NaN or Inf", reason="NaN/Inf")
        raise MessageError(f"{kind}: field '{names[i]}' has values beyond +-{max_abs:g}", reason="out of range")
    out = dict(zip(names, block, strict=True))
    if "s" in out and np.any(np.diff(out["s"]) <= 0.0):
        raise MessageError(f"{kind}: arclength 's' must increase strictly", reason="bad arclength grid")
    return out


@dataclass(frozen=True)
class ObjectArrays:
    """The movable object in a RodState message (SI): its ``centroid`` at the start pose (2,),
    displacement ``q`` and velocity ``v`` (3,) (:class:`~contgrasp_core.rod.body.BodyState`) and
    the external ``wrench`` (3,) held on it over the control period from this state."""

    centroid: Array
    q: Array
    v: Array
    wrench: Array


@dataclass(frozen=True)
class RodArrays:
    """Arrays of a RodState message (SI); ``object`` when the object moves (None: fixed)."""

    step: int
    t: float
    s: Array
    x: Array
    y: Array
    theta: Array
    kappa: Array
    radius: Array
    object: ObjectArrays | None = None

    @property
    def shape(self) -> ArmShape:
        """The centreline at the nodes (world frame)."""
        return ArmShape(s=self.s, r=np.stack([self.x, self.y], -1), theta=self.theta)

    @property
    def sensed_shape(self) -> ArmShape:
        """What :func:`contgrasp_core.contact.sense` senses against the object's boundary: the
        centreline, in the object's start-pose frame when the object moves (as the core loop,
        :func:`contgrasp_core.rod.session.sensed_shape`)."""
        if self.object is None:
            return self.shape
        return shape_in_object_frame(self.shape, self.object.q, self.object.centroid)


_OBJECT_FIELDS = (("object_centroid", 2), ("object_q", 3), ("object_v", 3), ("object_wrench", 3))


def object_fields(centroid: tuple[float, float] | None, body: BodyState | None, wrench: Array | None) -> dict[str, array[float]]:
    """The object fields of a RodState message: empty while the object is fixed (``body`` None);
    a movable object without an external wrench (``wrench`` None) carries zeros."""
    if centroid is None or body is None:
        return {name: array("d") for name, _ in _OBJECT_FIELDS}
    return {"object_centroid": float64_field(centroid), "object_q": float64_field(body.q), "object_v": float64_field(body.v),
            "object_wrench": float64_field(np.zeros(3) if wrench is None else wrench)}


def rod_state_fields(obs: Observation, header: Header | Any, centroid: tuple[float, float] | None,
                     wrench: Array | None) -> dict[str, Any]:
    """The fields of the RodState message of an observation (arrays as numpy arrays, for
    :class:`~contgrasp_ros.plumbing.cdr.Codec`); the object fields as :func:`object_fields` says."""
    return {"header": header, "step": obs.k, "s": obs.s, "x": obs.x[:, 0], "y": obs.x[:, 1], "theta": obs.theta,
            "kappa": obs.kappa, "radius": obs.radius, "vx": obs.v[:, 0], "vy": obs.v[:, 1],
            "kinetic_energy": obs.kinetic_energy, "max_penetration": obs.penetration,
            **object_fields(centroid, obs.body, wrench)}


def _object_arrays(msg: RodStateMsg) -> ObjectArrays | None:
    # (recordings made before the object could move have none of these fields)
    values = {name: np.asarray(getattr(msg, name, ()), dtype=float) for name, _ in _OBJECT_FIELDS}
    if all(v.size == 0 for v in values.values()):
        return None
    for name, n in _OBJECT_FIELDS:
        v = values[name]
        if v.shape != (n,):
            raise MessageError(f"RodState: field '{name}' must be empty (a fixed object) or have {n} values, got {v.size}",
                               reason="length mismatch")
        if not np.all(np.isfinite(v)):
            raise MessageError(f"RodState: field '{name}' contains NaN or Inf", reason="NaN/Inf")
        if np.any(np.abs(v) > MAX_ABS):
            raise MessageError(f"RodState: field '{name}' has values beyond +-{MAX_ABS:g}", reason="out of range")
    return ObjectArrays(values["object_centroid"], values["object_q"], values["object_v"], values["object_wrench"])


def rod_state_arrays(msg: RodStateMsg) -> RodArrays:
    """Validated arrays of a RodState message."""
    a = _arrays(msg, ("s", "x", "y", "theta", "radius"))
    if len(msg.kappa) not in (0, len(a["s"])):
        raise MessageError("RodState: field 'kappa' must be empty or have one value per node", reason="length mismatch")
    kappa = np.asarray(msg.kappa, dtype=float)
    if not np.all(np.isfinite(kappa)):
        raise MessageError("RodState: field 'kappa' contains NaN or Inf", reason="NaN/Inf")
    if np.any(a["radius"] < 0.0):
        raise MessageError("RodState: radius must be >= 0", reason="out of range")
    return RodArrays(int(msg.step), stamp_seconds(msg.header), a["s"], a["x"], a["y"], a["theta"], kappa, a["radius"],
                     _object_arrays(msg))


def wrench_arrays(msg: WrenchStamped) -> Array:
    """The planar wrench (fx, fy, torque) (3,) of a geometry_msgs/WrenchStamped in the world
    frame (force at the object's centroid, torque about it); the out-of-plane components must be 0."""
    f, m = msg.wrench.force, msg.wrench.torque
    w = np.array([f.x, f.y, m.z, f.z, m.x, m.y], dtype=float)
    if not np.all(np.isfinite(w)):
        raise MessageError("WrenchStamped: the wrench contains NaN or Inf", reason="NaN/Inf")
    if np.any(np.abs(w) > MAX_ABS):
        raise MessageError(f"WrenchStamped: values beyond +-{MAX_ABS:g}", reason="out of range")
    if np.any(w[3:] != 0.0):
        raise MessageError("WrenchStamped: the object moves in the plane: force.z, torque.x and torque.y must be 0",
                           reason="out of plane")
    if msg.header.frame_id not in ("", "world"):
        raise MessageError(f"WrenchStamped: frame '{msg.header.frame_id}' (the wrench is given in 'world')",
                           reason="wrong frame")
    return w[:3]


def contact_fields(state: ContactState, header: Header | Any, step: int,
                   shape: tuple[Array, Array] | None = None) -> dict[str, Any]:
    """The fields of the ContactState message of a sensed contact state (arrays as numpy
    arrays: for :class:`~contgrasp_ros.plumbing.cdr.Codec` or :func:`contact_to_msg`), with the
    arm's own shape ``(theta, kappa)`` at the nodes when given (what the holding law senses)."""
    fields = {"header": header, "step": int(step), "s": state.s, "rho": state.rho, "alpha": state.alpha,
              "delta": state.delta, "s_o": state.s_o, "shadow_x": state.foot[:, 0], "shadow_y": state.foot[:, 1],
              "in_contact": np.asarray(state.in_contact, dtype=bool), "contact_tolerance": float(state.tol)}
    if shape is not None:
        fields["theta"], fields["kappa"] = (np.asarray(a, dtype=float) for a in shape)
    return fields


def contact_to_msg(state: ContactState, header: Header, step: int,
                   shape: tuple[Array, Array] | None = None) -> ContactStateMsg:
    """ContactState message of a sensed contact state (and the arm's shape, :func:`contact_fields`)."""
    from contgrasp_msgs.msg import ContactState as ContactStateMsg

    return ContactStateMsg(**_typed(contact_fields(state, header, step, shape)))


def _typed(fields: dict[str, Any]) -> dict[str, Any]:
    """Message fields as the generated message classes take them fast: float64 arrays as
    ``array('d')`` (:func:`float64_field`), bool arrays as lists."""
    out = {}
    for name, value in fields.items():
        if isinstance(value, np.ndarray):
            value = value.tolist() if value.dtype == np.bool_ else float64_field(value)
        out[name] = value
    return out


@dataclass(frozen=True)
class ContactArrays:
    """Arrays of a ContactState message (SI); ``theta`` and ``kappa`` at the nodes, the arm's own
    shape, are empty when the message does not carry them (a recording made before they existed)."""

    step: int
    t: float
    s: Array
    rho: Array
    alpha: Array
    delta: Array
    s_o: Array
    shadow: Array
    in_contact: NDArray[np.bool_]
    tol: float
    theta: Array = dataclass_field(default_factory=lambda: np.empty(0))
    kappa: Array = dataclass_field(default_factory=lambda: np.empty(0))


def contact_arrays(msg: ContactStateMsg) -> ContactArrays:
    """Validated arrays of a ContactState message."""
    a = _arrays(msg, ("s", "rho", "alpha", "delta", "s_o", "shadow_x", "shadow_y"))
    if len(msg.in_contact) != len(a["s"]):
        raise MessageError(f"ContactState: 'in_contact' has {len(msg.in_contact)} flags for {len(a['s'])} nodes",
                           reason="length mismatch")
    flags = np.asarray(msg.in_contact, dtype=bool)
    tol = float(msg.contact_tolerance)
    if not np.isfinite(tol) or not 0.0 <= tol <= MAX_ABS:
        raise MessageError(f"ContactState: contact_tolerance must be finite and >= 0, got {tol}", reason="out of range")
    shape = {}
    if len(getattr(msg, "theta", ())) or len(getattr(msg, "kappa", ())):  # (the arm's shape, when sent)
        shape = _arrays(msg, ("s", "theta", "kappa"))
        del shape["s"]
    return ContactArrays(
        int(msg.step),
        stamp_seconds(msg.header),
        a["s"],
        a["rho"],
        a["alpha"],
        a["delta"],
        a["s_o"],
        np.stack([a["shadow_x"], a["shadow_y"]], -1),
        flags,
        tol,
        **shape,
    )


@dataclass(frozen=True)
class HeldShape:
    """The holding law's hold as a CoupleControl message carries it (eq. (H4) of
    docs/holding.md): the couple ``u`` (its held part ``-EI kappa_ref``), the rest curvature
    ``kappa_ref`` at the joints and the stiffness gain ``gain``. :meth:`hold` makes the
    :class:`~contgrasp_core.control.hold_law.ShapeHold` the rod engine applies."""

    u: Array
    kappa_ref: Array
    gain: float

    def hold(self, model: Any) -> ShapeHold:
        """The hold on ``model`` (a :class:`~contgrasp_core.rod.model.RodModel`), computed from
        ``kappa_ref`` and ``gain`` as the controller computed it; :class:`MessageError` when the
        message's ``u`` is not ``-EI kappa_ref`` of this rod (another rod's hold)."""
        held = ShapeHold(model, self.kappa_ref, self.gain)
        if not np.allclose(self.u, held.couple, rtol=1e-9, atol=0.0):
            raise MessageError("CoupleControl: u is not -EI kappa_ref of this rod's stiffness (a hold computed for "
                               "another rod?)", reason="inconsistent hold")
        return held


Couple = Array | FeedbackExpansion | HeldShape
"""What a CoupleControl message carries: a plain couple, the paper law's expansion or a hold."""


def couple_fields(s: Array, couple: Array | FeedbackExpansion | ShapeHold, header: Header | Any, step: int,
                  transition: bool = False) -> dict[str, Any]:
    """The fields of the CoupleControl message of the couple u (N m) at the joint arclengths s,
    with the law's first-order expansion when given a :class:`FeedbackExpansion`, or the
    holding law's rest curvature and gain when given a
    :class:`~contgrasp_core.control.hold_law.ShapeHold` (u its held part), and the law's
    ``transition`` flag (arrays as numpy arrays: for :class:`~contgrasp_ros.plumbing.cdr.Codec`
    or :func:`couple_to_msg`)."""
    fields = {"header": header, "step": int(step), "s": np.asarray(s, dtype=float), "transition": bool(transition)}
    if isinstance(couple, FeedbackExpansion):
        fields.update(u=couple.u, rho_ref=couple.rho_ref, alpha_ref=couple.alpha_ref, du_drho=couple.g_rho,
                      du_dalpha=couple.g_alpha)
    elif isinstance(couple, ShapeHold):
        fields.update(u=couple.couple, kappa_ref=np.asarray(couple.kappa_ref, dtype=float), hold_gain=float(couple.gain))
    else:
        fields["u"] = np.asarray(couple, dtype=float)
    return fields


def couple_to_msg(s: Array, couple: Array | FeedbackExpansion | ShapeHold, header: Header, step: int,
                  transition: bool = False) -> CoupleControl:
    """CoupleControl message of :func:`couple_fields`."""
    from contgrasp_msgs.msg import CoupleControl

    return CoupleControl(**_typed(couple_fields(s, couple, header, step, transition)))


def couple_arrays(msg: CoupleControl) -> tuple[int, Array, Couple, bool]:
    """Validated (step, s, couple, transition) of a CoupleControl message; the couple is a
    :class:`FeedbackExpansion` when the message carries the expansion, a :class:`HeldShape` when
    it carries a hold's ``kappa_ref`` (the expansion then empty), else the array u.
    ``transition``: the law is still moving to its hold (False in a message without the field)."""
    # The couple and the gains scale with the rod's stiffness: only finiteness is required of
    # them (an absurd but finite couple is the simulator's divergence detection's business).
    expansion = len(msg.rho_ref) + len(msg.alpha_ref) + len(msg.du_drho) + len(msg.du_dalpha) > 0
    transition = bool(getattr(msg, "transition", False))
    if len(getattr(msg, "kappa_ref", ())):
        if expansion:
            raise MessageError("CoupleControl: a hold (kappa_ref) and an expansion at once", reason="hold and expansion")
        gain = float(msg.hold_gain)
        if not (np.isfinite(gain) and gain >= 0.0):
            raise MessageError(f"CoupleControl: hold_gain must be finite and >= 0, got {gain}", reason="out of range")
        a = _arrays(msg, ("s", "u", "kappa_ref"), max_abs=None)
        return int(msg.step), a["s"], HeldShape(a["u"], a["kappa_ref"], gain), transition
    if not expansion:
        a = _arrays(msg, ("s", "u"), max_abs=None)
        return int(msg.step), a["s"], a["u"], transition
    a = _arrays(msg, ("s", "u", "rho_ref", "alpha_ref", "du_drho", "du_dalpha"), max_abs=None)
    exp = FeedbackExpansion(u=a["u"], rho_ref=a["rho_ref"], alpha_ref=a["alpha_ref"], g_rho=a["du_drho"], g_alpha=a["du_dalpha"])
    return int(msg.step), a["s"], exp, transition


def quality_to_msg(q: GraspQuality, header: Header, step: int, tol: float) -> GraspQualityMsg:
    """GraspQuality message of Q1..Q3 and W."""
    from contgrasp_msgs.msg import GraspQuality as GraspQualityMsg

    return GraspQualityMsg(
        header=header,
        step=int(step),
        w=float64_field(np.ravel(q.W)),
        q1=q.Q1,
        q2=q.Q2,
        q3=q.Q3,
        contact_length=q.contact_length,
        contact_tolerance=float(tol),
        valid=bool(q.has_contact),
    )


# parameter names of the analytic kinds (Boundary.kind), in ObjectSpec's order, and the ObjectSpec shape
_PARAM_ORDER = {
    "circle": ("R", "center_x", "center_y"),
    "ellipse": ("a", "b", "center_x", "center_y", "angle"),
    "deformed_circle": ("R", "amplitude", "lobes", "phase", "center_x", "center_y"),
}
_SHAPE = {"circle": "circle", "ellipse": "ellipse", "deformed_circle": "deformed"}


def boundary_to_msg(boundary: Boundary, header: Header, samples: int = 256) -> ObjectBoundary:
    """ObjectBoundary message: kind, named parameters and ``samples`` points equally spaced in s_o;
    a user's outline (kind ``points``) carries its own points instead, so the receiver rebuilds
    the very same curve (:func:`boundary_from_msg`)."""
    params = dict(boundary.params)
    center = params.pop("center", None)
    if center is not None:
        params["center_x"], params["center_y"] = float(center[0]), float(center[1])
    names, values = [], []
    for key, val in params.items():
        if isinstance(val, int | float) and not isinstance(val, bool):
            names.append(key)
            values.append(float(val))
    from contgrasp_msgs.msg import ObjectBoundary

    if boundary.kind == "points":
        pts = np.asarray(boundary.params["points"])
    else:
        _, pts = boundary.sample(samples)
    return ObjectBoundary(
        header=header,
        kind=boundary.kind,
        parameter_names=names,
        parameter_values=values,
        length=boundary.length,
        x=pts[:, 0].tolist(),
        y=pts[:, 1].tolist(),
    )


def boundary_from_msg(msg: ObjectBoundary) -> Boundary:
    """Rebuild the boundary: analytic kinds from their parameters, a user's outline from its
    points (with its ``smoothing``: the sender's curve exactly), anything else (Fourier curves)
    from the samples as a closed spline.

    Raises :class:`MessageError`: reason ``"length mismatch"`` / ``"too many samples"`` /
    ``"out of range"`` for malformed fields, ``"bad object: <error>"`` when the core refuses the
    object (e.g. ``bad object: SelfIntersectionError`` for an outline that crosses itself).
    """
    if len(msg.parameter_names) != len(msg.parameter_values):
        raise MessageError(f"ObjectBoundary: {len(msg.parameter_names)} parameter names for "
                           f"{len(msg.parameter_values)} values", reason="length mismatch")
    values = np.asarray(msg.parameter_values, dtype=float)
    if np.any(np.abs(values) > MAX_ABS):  # NaN/Inf are left to the core, which names the parameter
        raise MessageError(f"ObjectBoundary: parameter values beyond +-{MAX_ABS:g}", reason="out of range")
    params = dict(zip(msg.parameter_names, values.tolist(), strict=True))
    try:
        if msg.kind in _PARAM_ORDER:
            missing = [k for k in _PARAM_ORDER[msg.kind] if k not in params]
            if missing:
                raise MessageError(f"ObjectBoundary '{msg.kind}' lacks parameters {missing}", reason="bad object: missing parameters")
            v = [params[k] for k in _PARAM_ORDER[msg.kind]]
            shape_params = [p for k, p in zip(_PARAM_ORDER[msg.kind], v, strict=True) if k not in ('center_x', 'center_y', 'angle')]
            return ObjectSpec(_SHAPE[msg.kind], tuple(shape_params), (params['center_x'], params['center_y']),
                              params.get('angle', 0.0)).boundary()
        if len(msg.x) != len(msg.y):
            raise MessageError("ObjectBoundary: x and y differ in length", reason="length mismatch")
        if len(msg.x) > MAX_SAMPLES:
            raise MessageError(f"ObjectBoundary: {len(msg.x)} points, at most {MAX_SAMPLES} accepted", reason="too many samples")
        pts = np.stack([np.asarray(msg.x, dtype=float), np.asarray(msg.y, dtype=float)], -1)
        if np.any(np.abs(pts) > MAX_ABS):
            raise MessageError(f"ObjectBoundary: outline points beyond +-{MAX_ABS:g}", reason="out of range")
        smoothing = params.get("smoothing", 0.0) if msg.kind == "points" else 0.0
        return from_points(pts, closed=True, smoothing=smoothing)
    except MessageError:
        raise
    except ContgraspError as exc:
        raise MessageError(f"ObjectBoundary rejected: {exc}", reason=f"bad object: {type(exc).__name__}") from exc
