"""One model of a closed-loop grasp scenario (paper Sec. V-C and Appendix IV).

A :class:`Scenario` is everything that decides what a closed-loop run computes: the rod
(:class:`~contgrasp_core.rod.model.RodModel`), the object (:class:`~contgrasp_core.objects.ObjectSpec`),
the loop (:class:`~contgrasp_core.rod.closed_loop.ClosedLoopConfig`), the feedback gains
(:class:`GainSettings`) and what the sensor and the quality evaluator measure
(:class:`SensingSettings`). :data:`PAPER` is the paper's scenario as the ROS graph runs it.

The core runner, the ROS nodes (their parameter defaults), the launcher, the recorder's metadata
and ``contgrasp analyze`` all read it from here: :meth:`Scenario.to_ros_parameters` gives the
parameters per node (the layout of ``contgrasp_ros/config/default.yaml``, tested equal) and
:meth:`Scenario.from_ros_parameters` reads them back.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from contgrasp_core.control.gains import FeedbackGains, paper_gains
from contgrasp_core.control.hold_law import LAWS, HoldController, HoldLawSettings, Law, PaperLaw
from contgrasp_core.control.law import CENTIMETRE
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.objects import ROD_SCALE, ObjectSpec
from contgrasp_core.rod.body import ObjectDynamics
from contgrasp_core.rod.disturbance import Disturbance
from contgrasp_core.rod.closed_loop import ClosedLoopConfig
from contgrasp_core.rod.model import RodModel

if TYPE_CHECKING:
    from contgrasp_core.rod.integrator import RodSystem

__all__ = ["GainSettings", "SensingSettings", "Scenario", "PAPER", "ROD_PARAMETERS", "NODES", "SIMULATOR", "SENSOR",
           "CONTROLLER", "QUALITY", "object_from_parameters", "rod_from_parameters", "motion_from_parameters", "motion_parameters", "rod_system",
           "check_start", "HOLD_PREFIX", "OBJECT_PARAMETERS"]

SIMULATOR, SENSOR, CONTROLLER, QUALITY = "rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality"
NODES = (SIMULATOR, SENSOR, CONTROLLER, QUALITY)
"""The graph's nodes whose parameters the scenario sets."""

HOLD_PREFIX = "hold_"
"""The controller's parameters of the holding law: ``hold_<field>`` of :class:`HoldLawSettings`."""

ROD_PARAMETERS = ("length", "n_elements", "radius_base", "radius_tip", "density", "youngs_modulus", "damping",
                  "drag_normal", "drag_tangential", "contact_stiffness", "contact_damping", "friction", "friction_model",
                  "max_muscle_stress", "base_x", "base_y", "base_angle")
"""The rod's parameters (ROS names), shared by the simulator and the controller."""

OBJECT_PARAMETERS = ("object", "object_outline", "object_center", "object_angle")
"""The object's parameters (ROS names): the simulator's, and a copy in the controller's (the
planned hold's plan runs on the object)."""

_LOOP_PARAMETERS = ("duration", "control_period", "dt", "settle_speed", "settle_hold", "min_time")


@dataclass(frozen=True)
class GainSettings:
    """Gains of eq. (19): ``mu1``; ``mu2`` (law units) or, with ``adaptive_mu2``, the
    Appendix IV ``mu2(s) = r(s) - 1/(r_obj + r(s))`` with ``object_radius`` (m; None = the
    object's nominal radius); ``length_unit`` (metres per law unit, cm as in the paper)."""

    mu1: float = 1.0
    mu2: float = 0.0
    adaptive_mu2: bool = True
    object_radius: float | None = None
    length_unit: float = CENTIMETRE

    def gains(self, model: RodModel, obj: ObjectSpec) -> FeedbackGains:
        """The gains at the rod's joints."""
        if self.adaptive_mu2:
            r = obj.radius if self.object_radius is None else self.object_radius
            return paper_gains(model, r, mu1=self.mu1, length_unit=self.length_unit)
        return FeedbackGains(mu1=self.mu1, mu2=self.mu2, length_unit=self.length_unit)


@dataclass(frozen=True)
class SensingSettings:
    """The run's one contact set: ``contact_tolerance`` (m), a node is in contact where
    ``delta >= -contact_tolerance`` (paper Definition 1). The boundary sensor flags its contact
    states with it, and the grasp quality, the summaries' contact statistics and ``contgrasp
    analyze`` all use the flags and tolerance those states carry: one contact set per run. The
    default 0.5 mm counts the arm as touching where its surface is within 0.5 mm of the object
    (the rod's contact law lets it rest a few um off or into the surface; a zero tolerance keeps
    only a few nodes). ``quality_rate_hz``: quality evaluations per simulated second (0 = every
    contact state); ``reference``: the wrench reference point (m; None = the object's own,
    :attr:`Scenario.reference`)."""

    contact_tolerance: float = 0.0005
    quality_rate_hz: float = 20.0
    reference: tuple[float, float] | None = None


@dataclass(frozen=True)
class Scenario:
    """A closed-loop grasp: rod, object (its shape and how it moves: ``dynamics``, fixed by
    default, as in the paper), loop, gains and sensing (SI units); a scripted ``disturbance``
    on a movable object (None: none); the ``law`` (:data:`~contgrasp_core.control.hold_law.LAWS`:
    ``paper``, eq. (19), the default, ``hold``, the planned hold (P1) of docs/holding.md, or
    ``reactive``, its planner, the holding law (H1)-(H8) on what the arm senses; both with ``hold_law``).
    Its start is checked on construction (:func:`check_start`): the straight arm outside the
    object, the object within its reach."""

    rod: RodModel
    object: ObjectSpec
    loop: ClosedLoopConfig
    gains: GainSettings = field(default_factory=GainSettings)
    sensing: SensingSettings = field(default_factory=SensingSettings)
    dynamics: ObjectDynamics = field(default_factory=ObjectDynamics)
    disturbance: Disturbance | None = None
    law: str = "paper"
    hold_law: HoldLawSettings = field(default_factory=HoldLawSettings)

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise InvalidParameterError(f"unknown law {self.law!r}; the laws are {', '.join(LAWS)}")
        for name, cls in (("rod", RodModel), ("object", ObjectSpec), ("loop", ClosedLoopConfig),
                          ("gains", GainSettings), ("sensing", SensingSettings), ("dynamics", ObjectDynamics),
                          ("hold_law", HoldLawSettings)):
            if not isinstance(getattr(self, name), cls):
                raise InvalidParameterError(f"Scenario.{name} must be a {cls.__name__}, got {type(getattr(self, name)).__name__}")
        if self.disturbance is not None and not isinstance(self.disturbance, Disturbance):
            raise InvalidParameterError(f"Scenario.disturbance must be a Disturbance, got {type(self.disturbance).__name__}")
        _check_disturbance(self.dynamics, self.disturbance)
        check_start(self.rod, self.object)

    @property
    def feedback_gains(self) -> FeedbackGains:
        """The gains at the rod's joints (:meth:`GainSettings.gains`)."""
        return self.gains.gains(self.rod, self.object)

    def controller(self) -> Law:
        """A fresh controller of the scenario's law: the paper's fixed gains
        (:attr:`feedback_gains`), or the planned hold's playback from its start (its plan computed
        now: :class:`~contgrasp_core.holding.plan.PlannedHold`), or the reactive holding law's
        state at its start (the adaptive gain's object radius as the paper's)."""
        if self.law == "paper":
            return PaperLaw(self.feedback_gains)
        if self.law == "hold":
            from contgrasp_core.holding.plan import PlannedHold  # (holding imports the scenario)

            return PlannedHold.from_scenario(self)
        g = self.gains
        return HoldController(self.rod, self.object.radius if g.object_radius is None else g.object_radius,
                              self.hold_law, g.length_unit)

    def system(self) -> RodSystem:
        """The rod engine of this scenario: the rod, the object's obstacle and, unless the object
        is fixed, its rigid body."""
        return rod_system(self.rod, self.object, self.dynamics)

    @property
    def reference(self) -> tuple[float, float]:
        """The wrench reference point of the grasp map (m): the sensing's, else the object's
        own (:attr:`ObjectSpec.reference <contgrasp_core.objects.ObjectSpec.reference>`: an
        outline's centroid)."""
        return self.object.reference if self.sensing.reference is None else self.sensing.reference

    # ------------------------------------------------------------------ ROS parameters
    def to_ros_parameters(self) -> dict[str, dict[str, Any]]:
        """Parameters per node, plain types: ``{"/**": rod, "rod_simulator": object + loop, ...}``
        (the layout of a ROS 2 parameter file; ``/**`` applies to every node). The controller
        takes the ``law``, the holding law's settings as ``hold_<name>``
        (:class:`~contgrasp_core.control.hold_law.HoldLawSettings`), the ``control_period`` (the
        simulator's: the holding law's phases run in time) and the simulator's object parameters
        (``object``, ``object_outline``, ``object_center``, ``object_angle``: the planned hold's
        plan is computed on it; :meth:`from_ros_parameters` reads the simulator's)."""
        m = self.rod
        rod = {name: _plain(getattr(m, name)) for name in ROD_PARAMETERS if name not in ("base_x", "base_y")}
        rod["base_x"], rod["base_y"] = float(m.base_position[0]), float(m.base_position[1])
        rod = {k: rod[k] for k in ROD_PARAMETERS}
        o = self.object
        sim: dict[str, Any] = {"object": o.text() if o.shape != "outline" else "outline",
                               "object_outline": o.source if o.shape == "outline" else "",
                               "object_center": [float(c) for c in o.center], "object_angle": float(o.angle)}
        cfg = self.loop
        sim.update({"duration": cfg.duration, "control_period": float(cfg.control_period or 0.0), "dt": float(cfg.dt or 0.0),
                    "settle_speed": cfg.settle_speed, "settle_hold": cfg.settle_hold, "min_time": cfg.min_time})
        sim.update(motion_parameters(self.dynamics, self.disturbance))
        g = self.gains
        ctl = {"mu1": g.mu1, "mu2": g.mu2, "adaptive_mu2": g.adaptive_mu2,
               "object_radius": float(o.radius if g.object_radius is None else g.object_radius),
               "length_unit": g.length_unit, "law": self.law, "control_period": sim["control_period"]}
        ctl.update({name: list(sim[name]) if isinstance(sim[name], list) else sim[name] for name in OBJECT_PARAMETERS})
        ctl.update({f"{HOLD_PREFIX}{f.name}": float(getattr(self.hold_law, f.name)) for f in fields(HoldLawSettings)})
        s = self.sensing
        ref = self.reference
        quality = {"rate_hz": s.quality_rate_hz, "reference_x": float(ref[0]), "reference_y": float(ref[1])}
        return {"/**": rod, SIMULATOR: sim, SENSOR: {"contact_tolerance": s.contact_tolerance},
                CONTROLLER: ctl, QUALITY: quality}

    def node_parameters(self, node: str) -> dict[str, Any]:
        """The parameters of one node (the shared rod parameters included where the node takes them)."""
        p = self.to_ros_parameters()
        if node not in p:
            raise InvalidParameterError(f"unknown node {node!r}; the scenario sets {', '.join(NODES)}")
        shared = p["/**"] if node in (SIMULATOR, CONTROLLER) else {}
        return {**shared, **p[node]}

    @classmethod
    def from_ros_parameters(cls, params: dict[str, dict[str, Any]], base: Scenario | None = None) -> Scenario:
        """The scenario of a parameter set (per node, as :meth:`to_ros_parameters` or a loaded
        parameter file merged per node); what it omits comes from ``base`` (default :data:`PAPER`)."""
        base = PAPER if base is None else base
        default = base.to_ros_parameters()
        sim = {**default["/**"], **default[SIMULATOR], **params.get("/**", {}), **params.get(SIMULATOR, {})}
        ctl = {**default[CONTROLLER], **params.get(CONTROLLER, {})}
        sen = {**default[SENSOR], **params.get(SENSOR, {})}
        qual = {**default[QUALITY], **params.get(QUALITY, {})}
        rod = rod_from_parameters(sim)
        obj = object_from_parameters(sim["object"], sim["object_outline"], sim["object_center"], sim["object_angle"])
        loop = ClosedLoopConfig(duration=float(sim["duration"]), control_period=float(sim["control_period"]) or None,
                                dt=float(sim["dt"]) or None, settle_speed=float(sim["settle_speed"]),
                                settle_hold=float(sim["settle_hold"]), min_time=float(sim["min_time"]))
        gains = GainSettings(mu1=float(ctl["mu1"]), mu2=float(ctl["mu2"]), adaptive_mu2=bool(ctl["adaptive_mu2"]),
                             object_radius=float(ctl["object_radius"]), length_unit=float(ctl["length_unit"]))
        hold_law = HoldLawSettings(**{f.name: float(ctl[f"{HOLD_PREFIX}{f.name}"]) for f in fields(HoldLawSettings)})
        sensing = SensingSettings(contact_tolerance=float(sen["contact_tolerance"]),
                                  quality_rate_hz=float(qual["rate_hz"]),
                                  reference=(float(qual["reference_x"]), float(qual["reference_y"])))
        dynamics, disturbance = motion_from_parameters(sim)
        return cls(rod=rod, object=obj, loop=loop, gains=gains, sensing=sensing, dynamics=dynamics, disturbance=disturbance,
                   law=str(ctl["law"]), hold_law=hold_law)

    def with_object(self, obj: ObjectSpec, **changes: Any) -> Scenario:
        """The same scenario around another object (the adaptive gain follows its nominal radius, and
        a wrench reference that was the old object's own follows the new object's), with the other
        ``changes`` (fields, e.g. ``rod``) made at once: the start is checked (:func:`check_start`)
        on the new object with the new rod, not on a mix of old and new."""
        own = self.sensing.reference is not None and self.sensing.reference == self.object.reference
        changes.setdefault("sensing", replace(self.sensing, reference=obj.reference) if own else self.sensing)
        return replace(self, object=obj, gains=replace(self.gains, object_radius=None), **changes)


def rod_from_parameters(p: dict[str, Any]) -> RodModel:
    """The rod of a node's parameters (:data:`ROD_PARAMETERS`, all present)."""
    return RodModel(base_position=(float(p["base_x"]), float(p["base_y"])),
                    **{k: p[k] for k in ROD_PARAMETERS if k not in ("base_x", "base_y")})


def object_from_parameters(text: str, outline: str, center: Any, angle: float) -> ObjectSpec:
    """The object named by the simulator's parameters: ``object`` (``NAME[:PARAMS]`` in metres, or
    ``outline`` with the CSV file ``object_outline``), ``object_center`` [x, y] and ``object_angle``
    (rad, ellipses). An outline is placed by its own coordinates (centre and angle do not apply)."""
    if text == "outline" or outline:
        if text != "outline" or not outline:
            raise InvalidParameterError("an outline object needs object:=outline and object_outline:=FILE.csv")
        return ObjectSpec.from_outline(outline)
    spec = ObjectSpec.parse(text, ROD_SCALE)
    return ObjectSpec(spec.shape, spec.params, tuple(center), float(angle))


def motion_parameters(dynamics: ObjectDynamics, disturbance: Disturbance | None) -> dict[str, Any]:
    """The simulator's parameters of how the object moves and what pushes it (plain types; 0 for
    a mass or inertia taken from the density, ``disturbance_kind`` '' for no disturbance)."""
    d = disturbance
    return {"object_mode": dynamics.mode, "object_density": float(dynamics.areal_density),
            "object_mass": float(dynamics.mass or 0.0), "object_inertia": float(dynamics.inertia or 0.0),
            "object_stiffness": list(dynamics.stiffness), "object_damping": list(dynamics.damping),
            "disturbance_kind": "" if d is None else d.kind,
            "disturbance_wrench": [0.0, 0.0, 0.0] if d is None else list(d.wrench),
            "disturbance_start": 0.0 if d is None else float(d.start),
            "disturbance_duration": 0.0 if d is None else float(d.duration)}


def motion_from_parameters(p: dict[str, Any]) -> tuple[ObjectDynamics, Disturbance | None]:
    """The object's dynamics and scripted disturbance of the simulator's parameters
    (:func:`motion_parameters`); :class:`InvalidParameterError` for bad values (a negative mass,
    a stiffness that is not three numbers >= 0, a NaN wrench, a disturbance on a fixed object)."""
    mass, inertia = float(p["object_mass"]), float(p["object_inertia"])
    dynamics = ObjectDynamics(mode=str(p["object_mode"]), areal_density=float(p["object_density"]),
                              mass=None if mass == 0.0 else mass, inertia=None if inertia == 0.0 else inertia,
                              stiffness=_triple_parameter("object_stiffness", p["object_stiffness"]),
                              damping=_triple_parameter("object_damping", p["object_damping"]))
    disturbance = None
    if p["disturbance_kind"]:
        disturbance = Disturbance(kind=str(p["disturbance_kind"]),
                                  wrench=_triple_parameter("disturbance_wrench", p["disturbance_wrench"]),
                                  start=float(p["disturbance_start"]), duration=float(p["disturbance_duration"]))
    _check_disturbance(dynamics, disturbance)
    return dynamics, disturbance


def _triple_parameter(name: str, value: Any) -> tuple[float, float, float]:
    """Three numbers of an array parameter (what they must be is checked where they are used)."""
    try:
        x, y, z = (float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"{name} must be three numbers (x, y, rotation), got {value!r}") from exc
    return x, y, z


def _check_disturbance(dynamics: ObjectDynamics, disturbance: Disturbance | None) -> None:
    if disturbance is not None and dynamics.mode == "fixed":
        raise InvalidParameterError("a disturbance pushes a movable object: set the object's mode to spring or free")


def rod_system(rod: RodModel, obj: ObjectSpec, dynamics: ObjectDynamics) -> RodSystem:
    """The rod engine of a rod, the object's boundary (its obstacle) and, unless the object is
    fixed, its rigid body (what :meth:`Scenario.system`, ``contgrasp simulate`` and the simulator
    node build); :class:`InvalidParameterError` for a start :func:`check_start` refuses."""
    from contgrasp_core.rod.integrator import RodSystem
    from contgrasp_core.rod.obstacle import Obstacle

    check_start(rod, obj)
    boundary = obj.boundary()
    return RodSystem(rod, Obstacle(boundary), body=dynamics.body(boundary))


LARGE_OBJECT = 10.0
"""An object wider than this many arm lengths is taken for one in the wrong units (an outline in
the paper's dimensionless units is ~50 arm lengths wide): the start's error asks about metres."""


def check_start(rod: RodModel, obj: ObjectSpec) -> None:
    """Refuse a run whose start is geometrically impossible, before anything is simulated: the
    straight arm (along ``rod.base_angle`` from ``rod.base_position``, the engine's start) must
    lie outside the object, its surface (centreline signed distance minus the local radius
    ``r(s)``) included, and the object must be within reach (the base closer to the boundary than
    the arm is long). One projection of the arm's N + 1 nodes; :class:`InvalidParameterError`
    with one line naming the cause (and asking about the units when the object is much larger
    than the arm)."""
    s = rod.s_nodes
    heading = np.array([np.cos(rod.base_angle), np.sin(rod.base_angle)])
    nodes = np.asarray(rod.base_position, dtype=float) + s[:, None] * heading
    clearance = obj.boundary().project(nodes).signed_distance - rod.radius(s)
    x, y = rod.base_position
    base = f"base ({x:.4g}, {y:.4g})"
    depth = -float(clearance.min())
    if depth > 0.0:
        raise InvalidParameterError(
            f"the arm starts inside the object: its straight start at {base} heading {rod.base_angle:.4g} rad passes "
            f"{depth:.3g} m inside the object ({_describe(obj)}); move the base or shrink the object{_units_hint(rod, obj)}")
    gap = float(clearance[0] + rod.radius_base)  # the base's distance to the boundary (it is outside)
    if gap >= rod.length:
        raise InvalidParameterError(
            f"the object is out of the arm's reach: the {base} is {gap:.3g} m from the object ({_describe(obj)}) and "
            f"the arm is {rod.length:g} m long; move the base closer{_units_hint(rod, obj)}")


def _describe(obj: ObjectSpec) -> str:
    """The object in words, for :func:`check_start`'s messages."""
    p = obj.params
    if obj.shape == "circle":
        return f"circle of radius {p[0]:g} m"
    if obj.shape == "ellipse":
        return f"ellipse of semi-axes {p[0]:g} m and {p[1]:g} m"
    if obj.shape == "deformed":
        return f"deformed circle of radius {p[0]:g} m"
    return f"outline {obj.source or f'of {len(obj.points)} points'}"


def _units_hint(rod: RodModel, obj: ObjectSpec) -> str:
    """'; is the outline in metres? ...' when the object is more than :data:`LARGE_OBJECT` arm
    lengths wide, else ''."""
    _, pts = obj.boundary().sample(256)
    width = float(np.max(np.ptp(pts, axis=0)))
    if width <= LARGE_OBJECT * rod.length:
        return ""
    what = "outline" if obj.shape == "outline" else "object"
    return f"; is the {what} in metres? (it is {width:.3g} m wide, the arm is {rod.length:g} m long)"


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    return value


_PAPER_ROD = RodModel(length=0.20, n_elements=100, radius_base=0.01, radius_tip=0.001, density=1042.0,
                      youngs_modulus=1.0e4, damping=1.0, drag_normal=5110.0, drag_tangential=25.55,
                      contact_stiffness=1.0e5, contact_damping=1.0)

PAPER = Scenario(
    rod=_PAPER_ROD,
    object=ObjectSpec.parse("circle", ROD_SCALE),
    loop=ClosedLoopConfig(duration=4.0, control_period=0.002, settle_speed=0.002, settle_hold=0.3, min_time=1.0),
    gains=GainSettings(object_radius=0.025),
    sensing=SensingSettings(contact_tolerance=0.0005, quality_rate_hz=20.0, reference=(0.08, 0.08)),
)
"""The paper's closed-loop grasp (Sec. V-C, Appendix IV) as the ROS graph runs it: L = 20 cm tapered
1 cm -> 1 mm, octopus material and drag (density 1042 kg/m^3, E = 10 kPa, drag 5110 / 25.55), a
2.5 cm circle centred at (8, 8) cm, the adaptive mu2 of Appendix IV, a 2 ms control period
(the law held to first order in the state). The damping ``zeta = 1 /s`` and the contact law are
this project's choices (docs/rod.md)."""
