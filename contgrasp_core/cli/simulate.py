"""``contgrasp simulate``: the closed-loop grasp of paper Sec. V-C on the project's rod engine.

The arguments make one :class:`~contgrasp_core.scenario.Scenario` (:func:`scenario_from_args`),
which the core runs (:func:`run_scenario`): the sampled loop held to first order as the ROS
graph steps it, or the continuous or zero-order loop. ``func=simulate.run`` returns the JSON-able
result dict (``cli.main`` prints it); without ``parents`` the subcommand adds its own ``--json``.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.control.hold_law import Law
from contgrasp_core.holding.measure import check_reach
from contgrasp_core.rod import RodModel
from contgrasp_core.rod.body import MODES, ObjectDynamics, motion_summary
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, ClosedLoopResult, run_closed_loop
from contgrasp_core.rod.self_contact import self_gap
from contgrasp_core.rod.session import record_sampled
from contgrasp_core.objects import ROD_SCALE
from contgrasp_core.outputs import check_output
from contgrasp_core.scenario import PAPER, Scenario
from contgrasp_core.tracking import contact_stats

from .common import add_law_arguments, add_muscle_argument, add_object_arguments, hold_law_from_args, object_from_args, rod_from_args

__all__ = ["add_parser", "run", "scenario_from_args", "run_scenario", "summarize", "loop_config"]


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


def loop_config(args: argparse.Namespace, record_period: float | None = None) -> ClosedLoopConfig:
    """The run's settings: the scenario's loop (its settle criterion: every node slower than
    ``settle_speed`` for ``settle_hold`` s, not before ``min_time``, the same as the ROS graph's)
    with the command's duration, control period and integrator step (:func:`default_dt`)."""
    duration = PAPER.loop.duration if args.duration is None else args.duration
    config = replace(PAPER.loop, duration=duration, control_period=args.control_period,
                     dt=default_dt(args) if args.control_period is None else None, record_period=record_period)
    steps = config.duration / config.period
    if steps > MAX_STEPS:
        step = f"--control-period {config.period:g}" if args.control_period is not None else f"--dt {config.period:g}"
        raise InvalidParameterError(f"--duration {config.duration:g} s at {step} s is {steps:.3g} steps, more than "
                                    f"{MAX_STEPS:.0e}: shorten the duration or lengthen the step")
    return config


MAX_STEPS = 10_000_000
"""Most control periods (or continuous steps) of one ``simulate`` / ``hold`` run: hours of computing."""


RECORD_PERIOD = 0.01
"""How often a run is recorded (s): the series the figures draw; the JSON reports the final state."""

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
    stiffness or damping without ``--object-mode spring``, or an inertia for the fixed object, is
    a usage error)."""
    spring = args.object_mode == "spring"
    if not spring and (args.object_stiffness is not None or args.object_damping is not None):
        raise InvalidParameterError("--object-stiffness/--object-damping set the spring: give --object-mode spring")
    inertial = args.object_mass is not None or args.object_inertia is not None or args.object_density != ObjectDynamics().areal_density
    if args.object_mode == "fixed" and inertial:
        raise InvalidParameterError("--object-mass/--object-inertia/--object-density set a movable object's inertia: "
                                    "give --object-mode spring or free (the fixed object does not move)")
    stiffness = SPRING_DEFAULTS[0] if args.object_stiffness is None else tuple(args.object_stiffness)
    damping = SPRING_DEFAULTS[1] if args.object_damping is None else tuple(args.object_damping)
    return ObjectDynamics(mode=args.object_mode, areal_density=args.object_density, mass=args.object_mass,
                          inertia=args.object_inertia, stiffness=stiffness if spring else (0.0, 0.0, 0.0),
                          damping=damping if spring else (0.0, 0.0, 0.0))


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    """The scenario of the command line: the paper's (:data:`~contgrasp_core.scenario.PAPER`)
    around the object, with the rod of ``--nodes``, ``--damping``, ``--friction`` and
    ``--max-muscle-stress``, the loop of :func:`loop_config`, the object's motion
    (:func:`object_dynamics`), the law and its settings, and the contact tolerance; an input error
    for a value out of range or an impossible start (:func:`~contgrasp_core.scenario.check_start`)."""
    if not 3 <= args.nodes <= MAX_NODES:
        raise InvalidParameterError(f"--nodes must be in [3, {MAX_NODES}], got {args.nodes}")
    if not (np.isfinite(args.contact_tol) and args.contact_tol >= 0.0):
        raise InvalidParameterError(f"--contact-tol must be a finite number >= 0, got {args.contact_tol}")
    if args.dt is not None and not (np.isfinite(args.dt) and args.dt > 0.0):  # (checked also when unused)
        raise InvalidParameterError(f"--dt must be a finite number > 0, got {args.dt}")
    obj = object_from_args(args, ROD_SCALE)
    if not (np.isfinite(args.friction) and args.friction >= 0.0):
        raise InvalidParameterError(f"--friction must be a finite number >= 0, got {args.friction}")
    changes: dict[str, Any] = {} if args.damping is None else {"damping": args.damping}
    if args.friction > 0:
        changes.update(friction=args.friction, friction_model="stick")
    rod = rod_from_args(args, **changes)
    hold_law = hold_law_from_args(args)
    if args.hold != "zero-order" and args.control_period is None:
        raise InvalidParameterError(f"--hold {args.hold} holds a sampled couple: give --control-period too")
    return PAPER.with_object(obj, rod=rod, loop=loop_config(args), dynamics=object_dynamics(args), law=args.law,
                             hold_law=hold_law, sensing=replace(PAPER.sensing, contact_tolerance=args.contact_tol))


def run_scenario(scenario: Scenario, law: Law, hold: str = "first-order",
                 record_period: float | None = RECORD_PERIOD) -> ClosedLoopResult:
    """The core's run of ``scenario`` with ``law`` (a fresh :meth:`~contgrasp_core.scenario.Scenario.controller`),
    recorded every ``record_period``: a sampled loop held to first order, as the ROS graph steps
    it (:func:`~contgrasp_core.rod.session.record_sampled`), else
    :func:`~contgrasp_core.rod.closed_loop.run_closed_loop` (continuous, or sampled and held
    constant: ``hold`` ``zero-order``)."""
    if hold == "first-order" and scenario.loop.control_period is not None:
        return record_sampled(scenario, record_period, law)
    return run_closed_loop(scenario.system(), scenario.feedback_gains, replace(scenario.loop, record_period=record_period),
                           law=law)


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the scenario; write the plot/animation if asked; return the JSON-able result."""
    if args.plot:
        from contgrasp_core.figures.draw import check_figure_path

        check_figure_path(args.plot)
    if args.animate:
        _check_animation_path(args.animate)
    scenario = scenario_from_args(args)
    check_reach(scenario)  # (the holding law's cage must be able to close: refused before simulating)
    warning = zoh_warning(scenario.rod, scenario.loop.control_period, args.hold)
    if warning:
        print(f"contgrasp simulate: {warning}", file=sys.stderr)
    law = scenario.controller()
    res = run_scenario(scenario, law, args.hold)
    out = summarize(res, scenario.sensing.contact_tolerance, "zoh" if args.hold == "zero-order" else "first-order hold")
    out.update(object=scenario.object.text(), object_mode=scenario.dynamics.mode, law=scenario.law,
               law_phase=getattr(law, "phase", None), friction=scenario.rod.friction)
    warning = validity_warning(out)
    if warning:
        print(f"contgrasp simulate: {warning}", file=sys.stderr)
    obj = scenario.object
    boundary = obj.boundary()
    if args.plot:
        from contgrasp_core.figures.closed_loop import plot_fig4

        # (the static solution is the paper's law's equilibrium: drawn for it only)
        plot_fig4(res, boundary, args.plot, obj.radius if boundary.kind == "circle" and scenario.law == "paper" else None)
    if args.animate:
        from contgrasp_core.figures.closed_loop import animate

        animate(res, boundary, args.animate)
    return out
