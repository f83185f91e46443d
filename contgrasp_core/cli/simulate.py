"""``contgrasp simulate``: the closed-loop grasp of paper Sec. V-C on the project's rod engine.

Wire-up (in ``cli/__init__.py``): ``simulate.add_parser(sub, [common])``; the parsed namespace has
``func=simulate.run``, which returns the JSON-able result dict (``cli.main`` prints it).
Without ``parents`` the subcommand adds its own ``--json`` flag.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.control import FeedbackGains, paper_gains
from contgrasp_core.control.hold_law import LAWS, HoldController, HoldLawSettings, Law, ShapeHold, check_law_settings
from contgrasp_core.figures.closed_loop import animate, plot_fig4
from contgrasp_core.rod import RodModel, RodSystem
from contgrasp_core.rod.body import MODES, ObjectDynamics, motion_summary
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, ClosedLoopResult, object_motion, run_closed_loop
from contgrasp_core.rod.self_contact import self_gap
from contgrasp_core.objects import ROD_SCALE
from contgrasp_core.outputs import check_output
from contgrasp_core.scenario import PAPER, rod_system
from contgrasp_core.tracking import contact_stats

from .common import add_muscle_argument, add_object_arguments, object_from_args

__all__ = ["add_parser", "run", "summarize", "loop_config", "add_law_arguments", "hold_law_from_args"]


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser] | None = None) -> argparse.ArgumentParser:
    """Register the ``simulate`` subcommand (``parents`` e.g. the CLI's common ``--json/--debug``)."""
    p = subparsers.add_parser("simulate", help="closed-loop grasp on the Cosserat rod engine (paper Sec. V-C)",
                              description=__doc__.splitlines()[0], parents=parents or [])
    add_object_arguments(p, ROD_SCALE)
    p.add_argument("--duration", type=float, default=None,
                   help="max simulated time, s (a fixed object: stops earlier when settled; a movable one is watched "
                   f"for the whole duration, settled if quiet at the end; default: the scenario's, {PAPER.loop.duration} s)")
    p.add_argument("--control-period", type=float, default=None,
                   help="sample-and-hold period of the feedback, s (default: continuous implicit feedback)")
    p.add_argument("--hold", choices=HOLDS, default="zero-order",
                   help="how a sampled couple is held over --control-period: zero-order (constant; unstable for "
                   "the paper's law at periods >= 1 ms, see docs/ros.md) or first-order in the state, as the ROS "
                   "graph does (default zero-order)")
    p.add_argument("--dt", type=float, default=None,
                   help=f"largest integrator step of the continuous loop, s (default {FIXED_DT:g} with a fixed object, "
                   f"{MOVABLE_DT:g}, the graph's control period, with a movable one: coarser steps damp a free object's "
                   "escape numerically, docs/holding.md)")
    p.add_argument("--nodes", type=int, default=101, help="rod nodes (elements + 1)")
    p.add_argument("--damping", type=float, default=None, help="damping zeta, 1/s (default: scenario value)")
    p.add_argument("--contact-tol", type=float, default=PAPER.sensing.contact_tolerance,
                   help="contact tolerance, m: in contact where delta >= -tol (default: the scenario's, "
                        f"{PAPER.sensing.contact_tolerance} m, as the ROS graph's sensor)")
    if not parents:
        p.add_argument("--json", action="store_true", help="print the result as JSON")
    g = p.add_argument_group("a movable object (beyond the paper; docs/rod.md)")
    g.add_argument("--object-mode", choices=MODES, default="fixed",
                   help="fixed (the paper's immovable object, default), spring (held to its start pose by a "
                   "spring-damper) or free")
    d = ObjectDynamics()
    g.add_argument("--object-density", type=float, default=d.areal_density,
                   help=f"areal density, kg/m^2: mass and inertia from the enclosed area (default {d.areal_density:g})")
    g.add_argument("--object-mass", type=float, default=None, help="mass, kg (instead of the density's)")
    g.add_argument("--object-inertia", type=float, default=None,
                   help="moment of inertia about the centroid, kg m^2 (instead of the density's)")
    g.add_argument("--object-stiffness", type=float, nargs=3, metavar=("KX", "KY", "KPSI"), default=None,
                   help="spring to the start pose: N/m, N/m, N m/rad (spring mode; default 50 50 0.05)")
    g.add_argument("--object-damping", type=float, nargs=3, metavar=("CX", "CY", "CPSI"), default=None,
                   help="damper to the start pose: N s/m, N s/m, N m s/rad (spring mode; default 1 1 0.001)")
    p.add_argument("--friction", type=float, default=PAPER.rod.friction,
                   help="Coulomb friction coefficient of the contact, stick-slip (docs/rod.md; default: the "
                   f"paper's frictionless contact, {PAPER.rod.friction:g})")
    add_muscle_argument(p)
    add_law_arguments(p)
    p.add_argument("--plot", metavar="FILE", help="write the paper's Fig. 4 (PNG/PDF/SVG)")
    p.add_argument("--animate", metavar="FILE.gif", help="write an animation of the grasp")
    p.set_defaults(func=run)
    return p


def add_law_arguments(p: argparse.ArgumentParser) -> None:
    """``--law`` and the holding law's parameters (docs/holding.md (H1)-(H6))."""
    d = HoldLawSettings()
    g = p.add_argument_group("the closed loop's law (docs/holding.md, 'A law that holds')")
    g.add_argument("--law", choices=LAWS, default="paper",
                   help="paper: eq. (19) with rho_d = r (default); hold: cage at a clearance, close, hold the "
                   "shape and squeeze (beyond the paper)")
    g.add_argument("--clearance", type=float, default=d.clearance,
                   help=f"hold: the cage's gap to the object, m (default {d.clearance:g})")
    g.add_argument("--close-gap", type=float, default=d.close_gap,
                   help=f"hold: the gap at which the shape is latched, m, below the clearance (default {d.close_gap:g})")
    g.add_argument("--squeeze", type=float, default=d.squeeze,
                   help=f"hold: how deep the held shape presses into the object, m (default {d.squeeze:g})")
    g.add_argument("--hold-gain", type=float, default=d.stiffness_gain,
                   help=f"hold: the held shape's stiffness gain G >= 0 (default {d.stiffness_gain:g})")
    g.add_argument("--depth-gain", type=float, default=d.depth_gain,
                   help="hold: after the squeeze, regulate the mean sensed contact depth to --squeeze with this "
                   f"integral gain, 1/s >= 0 (docs/holding.md (H7); default {d.depth_gain:g}: off)")
    g.add_argument("--dwell", type=float, default=d.dwell,
                   help="hold: stay at the close gap this long, s >= 0, and latch the mean curvature over it "
                   f"(docs/holding.md (H8); default {d.dwell:g}: the one sample at which the gap is reached)")


def hold_law_from_args(args: argparse.Namespace) -> HoldLawSettings:
    """The holding law's parameters of the command line, refused with an input error when out of
    range or given to the paper's law, which ignores them (:func:`~contgrasp_core.control.hold_law.check_law_settings`)."""
    settings = HoldLawSettings(clearance=args.clearance, close_gap=args.close_gap, squeeze=args.squeeze,
                               stiffness_gain=args.hold_gain, depth_gain=args.depth_gain, dwell=args.dwell)
    check_law_settings(args.law, settings, lambda name: "--hold-gain" if name == "stiffness_gain" else f"--{name.replace('_', '-')}")
    return settings


def summarize(res: ClosedLoopResult, contact_tol: float = PAPER.sensing.contact_tolerance, hold: str = "zoh") -> dict[str, Any]:
    """The JSON result: final shape and contact state along s, settle data, penetration and the
    tracking statistics over the contact set ``delta >= -contact_tol`` (m, paper Definition 1;
    :func:`contgrasp_core.tracking.contact_stats`, as the ROS graph's summary)."""
    m = res.model
    r = m.radius(m.s_nodes)
    rho, alpha = res.rho[-1], res.alpha[-1]
    delta = r - rho
    stats = contact_stats(m.s_nodes, rho, delta, alpha, delta >= -contact_tol, contact_tol)
    return {
        "final": {"s": m.s_nodes.tolist(), "x": res.x[-1][:, 0].tolist(), "y": res.x[-1][:, 1].tolist(),
                  "theta": res.theta[-1].tolist(), "rho": rho.tolist(), "alpha": alpha.tolist()},
        "settled": bool(res.settled),
        "settle_time_s": res.settle_time,
        "sim_time_s": float(res.t[-1]),
        "steps": int(res.steps),
        "integrator_steps": int(res.integrator_steps),
        "wall_time_s": float(res.wall_time),
        "newton_iterations": int(res.newton_iterations),
        "max_penetration": float(res.max_penetration),
        "max_penetration_ratio": float(res.max_penetration_ratio),
        "final_penetration": float(res.penetration[-1]),
        "final_penetration_ratio": float(res.penetration_ratio[-1]),
        "contact_tolerance": float(contact_tol),
        **asdict(stats),
        **run_health(res),
        "damping_per_s": m.damping,
        "control": (f"continuous, steps <= {res.config.period:g} s" if res.config.control_period is None
                    else f"{hold} {res.config.control_period} s"),
        **_object_motion(res),
    }


def run_health(res: ClosedLoopResult) -> dict[str, Any]:
    """The run's ``validity`` block, the muscles' effort (``peak_couple``...) and the final
    ``self_gap`` (m, the smallest gap between parts of the arm that are not neighbours)."""
    assert res.health is not None  # (both runners measure it)
    gap = self_gap(res.model, res.final_state.theta).gap
    return {"validity": res.health.validity(), **res.health.effort(), "self_gap": None if np.isinf(gap) else gap}


def validity_warning(out: dict[str, Any]) -> str | None:
    """The one warning line of a run that left the model's validity (None when valid)."""
    broken = out["validity"]["broken"]
    return None if not broken else "warning: the run left the model's validity, so it is not settled: " + "; ".join(broken)


def _object_motion(res: ClosedLoopResult) -> dict[str, Any]:
    """A movable object's final displacement from its start pose and velocity (None when fixed)."""
    body = res.final_state.body
    return motion_summary(None, None) if body is None else motion_summary(body.q, body.v)


FIXED_DT = 0.01
"""The continuous loop's largest step with a fixed object (s): the paper's runs."""

MOVABLE_DT = 0.002
"""The continuous loop's largest step with a movable object (s), the graph's control period.
Measured on the holding law released free (docs/holding.md, "Resolved in time"): at 5 and 10 ms
the implicit step's numerical damping keeps the object (3.7, 4.5 mm), at 4, 3, 2, 1 and 0.5 ms
it escapes (190-230 mm), as in the sampled loop and the graph."""


def default_dt(args: argparse.Namespace) -> float:
    """``--dt`` as given, else :data:`FIXED_DT` or, with a movable object, :data:`MOVABLE_DT`."""
    if args.dt is not None:
        return float(args.dt)
    return FIXED_DT if getattr(args, "object_mode", "fixed") == "fixed" else MOVABLE_DT


def loop_config(args: argparse.Namespace, record_period: float | None = 0.01) -> ClosedLoopConfig:
    """The run's settings: the scenario's loop (its settle criterion: every node slower than
    ``settle_speed`` for ``settle_hold`` s, not before ``min_time``, the same as the ROS graph's)
    with the command's duration, control period and integrator step (:func:`default_dt`)."""
    duration = PAPER.loop.duration if args.duration is None else args.duration
    return replace(PAPER.loop, duration=duration, control_period=args.control_period,
                   dt=default_dt(args) if args.control_period is None else None, record_period=record_period)


HOLDS = ("zero-order", "first-order")

ZOH_UNSTABLE_PERIOD = 1e-3
"""Zero-order holds of the paper's law at or above this period are known (measured) to flutter or
crumple the paper's arm, whose tapered tip has bending modes of ~1000 rad/s (docs/rod.md,
docs/ros.md: 1, 2 and 10 ms); 0.5 ms agrees with the continuous loop over a short horizon."""


def zoh_warning(model: RodModel, period: float | None, hold: str) -> str | None:
    """The one-line warning for a zero-order hold known to be unstable: the paper's law held at a
    period of 1 ms or more on a rod whose tip is no stiffer than the paper's (per unit length and
    inertia: the fastest bending rate scales as sqrt(EI / (rho A)) / h^2, so a thinner, softer or
    finer-meshed tip is faster still), or None."""
    if period is None or hold != "zero-order":
        return None
    paper = PAPER.rod
    rate = _tip_rate(model) / _tip_rate(paper)  # >= 1: this rod's tip is at least as fast as the paper's
    if period * rate < ZOH_UNSTABLE_PERIOD * (1.0 - 1e-9):
        return None
    return (f"warning: a zero-order hold of the feedback law at --control-period {period:g} s is unstable for this rod "
            f"(measured for the paper's arm at >= {ZOH_UNSTABLE_PERIOD * 1e3:g} ms: the tip flutters and the run does not "
            "settle); use --hold first-order (what the ROS graph does) or leave out --control-period")


def _tip_rate(model: RodModel) -> float:
    """A measure of the fastest bending rate of the rod's discretisation: sqrt(EI / (rho A)) / h^2
    at the tip element (1/s up to a constant)."""
    s_tip = np.array([model.s_centres[-1]])
    ei = float(model.bending_stiffness(s_tip)[0])
    r = float(model.radius(s_tip)[0])
    return float(np.sqrt(ei / (model.density * np.pi * r**2)) / model.h**2)


def run_first_order(system: RodSystem, gains: FeedbackGains, config: ClosedLoopConfig,
                    law: Law | None = None) -> ClosedLoopResult:
    """The sampled loop with the couple held to first order in the state between samples
    (:class:`~contgrasp_core.control.HeldExpansion`, stepped by :class:`~contgrasp_core.rod.session.LoopSession`
    exactly as the ROS graph steps it), recorded like :func:`run_closed_loop`; with a ``law``
    its command each period (the holding law's hold applied exactly)."""
    import time

    from contgrasp_core.contact import sense
    from contgrasp_core.control import FeedbackExpansion, feedback_at_joints
    from contgrasp_core.rod import chain
    from contgrasp_core.rod.muscle import saturate
    from contgrasp_core.rod.session import LoopSession

    m = system.model
    assert system.obstacle is not None and config.control_period is not None
    rec_every = 1 if config.record_period is None else max(1, int(round(config.record_period / config.control_period)))
    rec: dict[str, list[Any]] = {k: [] for k in ("t", "x", "theta", "rho", "alpha", "couple", "pen", "ratio", "speed", "q")}
    wall0 = time.perf_counter()
    session = LoopSession(system, config)
    period = config.control_period
    max_ratio = 0.0
    while True:
        obs = session.observe(True if law is None else law.holding)
        obstacle = system.obstacle_at(session.state)  # (a movable object: sensed where it is, as the graph does)
        sn = sense(obs.shape, obstacle, obs.radius)
        command = gains if law is None else law.command(sn.rho, sn.alpha, obs.theta, obs.kappa[:-1], period)
        expansion: FeedbackExpansion | ShapeHold
        if isinstance(command, ShapeHold):
            expansion = command
            couple = saturate(m, command.couple + command.couple_and_jacobian(session.state.theta, jacobian=False)[0])
        else:
            expansion = feedback_at_joints(m, command, sn.rho, sn.alpha)
            couple = saturate(m, expansion.u)
        pen_c = m.r_centres - obstacle.project(chain.centres(m, session.state.theta)).signed_distance
        ratio = max(float((sn.delta / obs.radius).max()), float((pen_c / m.r_centres).max()), 0.0)
        max_ratio = max(max_ratio, ratio)
        if session.k % rec_every == 0 or session.finished:
            for key, val in (("t", obs.t), ("x", obs.x), ("theta", obs.theta), ("rho", sn.rho), ("alpha", sn.alpha),
                             ("couple", couple), ("pen", obs.penetration), ("ratio", ratio),
                             ("speed", obs.max_speed), ("q", None if session.state.body is None else session.state.body.q)):
                rec[key].append(val)
        if session.finished:
            break
        session.advance(expansion)
    arr = {k: np.asarray(v) for k, v in rec.items()}
    return ClosedLoopResult(
        t=arr["t"], x=arr["x"], theta=arr["theta"], rho=arr["rho"], alpha=arr["alpha"], couple=arr["couple"],
        penetration=arr["pen"], penetration_ratio=arr["ratio"], max_speed=arr["speed"], settled=session.settled,
        settle_time=session.settle_time, wall_time=time.perf_counter() - wall0, newton_iterations=session.iterations,
        final_state=session.state, model=m, gains=gains, config=config, steps=session.k,
        integrator_steps=session.k * config.substeps, max_penetration=session.max_penetration,
        max_penetration_ratio=max_ratio, health=session.health, **object_motion(system, rec["q"], law))


MAX_NODES = 10_001
"""Largest rod the command accepts (the paper's arm has 101 nodes)."""


def _check_animation_path(path: str) -> None:
    from pathlib import Path

    from PIL import Image

    p = Path(path)
    fmt = Image.registered_extensions().get(p.suffix.lower())
    if fmt not in ("GIF", "WEBP", "PNG"):
        raise InvalidParameterError(f"--animate {path}: use a .gif, .webp or .png file name")
    check_output(p, "--animate")


SPRING_DEFAULTS = ((50.0, 50.0, 0.05), (1.0, 1.0, 0.001))
"""The spring mode's stiffness and damping when not given (N/m, N/m, N m/rad; N s/m, N s/m, N m s/rad)."""


def object_dynamics(args: argparse.Namespace) -> ObjectDynamics:
    """How the object moves, from ``--object-mode`` and the ``--object-*`` options (a spring's
    stiffness or damping without ``--object-mode spring`` is a usage error)."""
    spring = args.object_mode == "spring"
    if not spring and (args.object_stiffness is not None or args.object_damping is not None):
        raise InvalidParameterError("--object-stiffness/--object-damping set the spring: give --object-mode spring")
    stiffness = SPRING_DEFAULTS[0] if args.object_stiffness is None else tuple(args.object_stiffness)
    damping = SPRING_DEFAULTS[1] if args.object_damping is None else tuple(args.object_damping)
    return ObjectDynamics(mode=args.object_mode, areal_density=args.object_density, mass=args.object_mass,
                          inertia=args.object_inertia, stiffness=stiffness if spring else (0.0, 0.0, 0.0),
                          damping=damping if spring else (0.0, 0.0, 0.0))


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the scenario; write the plot/animation if asked; return the JSON-able result."""
    if not 3 <= args.nodes <= MAX_NODES:
        raise InvalidParameterError(f"--nodes must be in [3, {MAX_NODES}], got {args.nodes}")
    if not (np.isfinite(args.contact_tol) and args.contact_tol >= 0.0):
        raise InvalidParameterError(f"--contact-tol must be a finite number >= 0, got {args.contact_tol}")
    if args.dt is not None and not (np.isfinite(args.dt) and args.dt > 0.0):  # (checked also when unused)
        raise InvalidParameterError(f"--dt must be a finite number > 0, got {args.dt}")
    if args.plot:
        from contgrasp_core.figures.draw import check_figure_path

        check_figure_path(args.plot)
    if args.animate:
        _check_animation_path(args.animate)
    obj = object_from_args(args, ROD_SCALE)
    boundary, r_obj = obj.boundary(), obj.radius
    if not (np.isfinite(args.friction) and args.friction >= 0.0):
        raise InvalidParameterError(f"--friction must be a finite number >= 0, got {args.friction}")
    overrides: dict[str, Any] = {"max_muscle_stress": args.max_muscle_stress}
    if args.damping is not None:
        overrides["damping"] = args.damping
    if args.friction > 0:
        overrides.update(friction=args.friction, friction_model="stick")
    model = replace(PAPER.rod, n_elements=args.nodes - 1, **overrides)
    hold_law = hold_law_from_args(args)
    if args.hold != "zero-order" and args.control_period is None:
        raise InvalidParameterError(f"--hold {args.hold} holds a sampled couple: give --control-period too")
    cfg = loop_config(args)
    system = rod_system(model, obj, object_dynamics(args))  # (refuses an impossible start: check_start)
    warning = zoh_warning(model, args.control_period, args.hold)
    if warning:
        print(f"contgrasp simulate: {warning}", file=sys.stderr)
    gains = paper_gains(model, r_obj)
    law = HoldController(model, r_obj, hold_law) if args.law == "hold" else None
    if args.hold == "first-order":
        res = run_first_order(system, gains, cfg, law)
    else:
        res = run_closed_loop(system, gains, cfg, law=law)
    out = summarize(res, args.contact_tol, "zoh" if args.hold == "zero-order" else "first-order hold")
    out.update(object=obj.text(), object_mode=args.object_mode, law=args.law, law_phase=None if law is None else law.phase,
               friction=model.friction)
    warning = validity_warning(out)
    if warning:
        print(f"contgrasp simulate: {warning}", file=sys.stderr)
    if args.plot:
        # (the static solution is the paper's law's equilibrium: drawn for it only)
        plot_fig4(res, boundary, args.plot, r_obj if boundary.kind == "circle" and args.law == "paper" else None)
    if args.animate:
        animate(res, boundary, args.animate)
    return out
