"""``contgrasp hold``: how firmly a closed loop holds the object (beyond the paper).

Grasps the object with the scenario's closed loop (object fixed, as in the paper; ``--law``
the paper's eq. (19) or the holding law of docs/holding.md), releases it onto a soft support
(``--support 0``: entirely free) with stick-slip friction, and measures the grasp stiffness
matrix K and the holding capacity per wrench direction
(:func:`contgrasp_core.holding.measure_holding`), beside Q1-Q3 of the settled contact (paper
Sec. IV). A grasp that lets the released object go is reported as not held (a result). The
arguments make one :class:`~contgrasp_core.scenario.Scenario` (:func:`scenario_from_args`) and
the loading's :class:`~contgrasp_core.holding.HoldSettings` (:func:`settings_from_args`).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import numpy as np

from ..control.hold_law import HOLDING_LAWS
from ..errors import InvalidParameterError
from ..holding import HoldSettings, measure_holding
from ..holding.measure import cage_capacity, check_reach
from ..objects import ROD_SCALE
from ..scenario import PAPER, Scenario
from .common import add_law_arguments, add_muscle_argument, add_object_arguments, hold_law_from_args, object_from_args, rod_from_args

__all__ = ["add_parser", "run", "format_text", "scenario_from_args", "settings_from_args"]


def add_parser(sub: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Register the ``hold`` subcommand."""
    d = HoldSettings()
    p = sub.add_parser("hold", parents=parents, description=__doc__.splitlines()[0],
                       help="grasp stiffness K and holding capacity of one settled grasp, with Q1-Q3 (docs/holding.md)")
    add_object_arguments(p, ROD_SCALE)
    p.add_argument("--nodes", type=int, default=PAPER.rod.n_elements + 1, help="rod nodes (elements + 1; default 101)")
    p.add_argument("--base", type=float, nargs=3, metavar=("X", "Y", "ANGLE"), default=None,
                   help="the arm's base position (m) and heading (rad) (default: the scenario's, 0 0 0)")
    p.add_argument("--mu", type=float, default=d.mu, help=f"friction coefficient, stick-slip (default {d.mu:g})")
    p.add_argument("--support", type=float, default=d.support,
                   help=f"stiffness of the released object's support, N/m; 0: released entirely free (default {d.support:g})")
    p.add_argument("--density", type=float, default=d.areal_density,
                   help=f"the object's areal density, kg/m^2 (default {d.areal_density:g})")
    p.add_argument("--directions", type=int, default=d.directions,
                   help=f"force directions of the capacity ramps, plus two pure torques (default {d.directions})")
    add_ramp_arguments(p, d)
    p.add_argument("--escape-distance", type=float, default=d.escape_distance,
                   help=f"escaped beyond this displacement, in object radii (default {d.escape_distance:g})")
    p.add_argument("--escape-angle", type=float, default=d.escape_angle,
                   help=f"escaped beyond this rotation, rad (default {d.escape_angle:g})")
    add_muscle_argument(p)
    add_law_arguments(p)
    p.set_defaults(func=run, format_text=format_text)


def add_ramp_arguments(p: argparse.ArgumentParser, d: HoldSettings) -> None:
    """The capacity ramp's ``--rate`` and ``--ramp-time`` and the first touch's ``--contact-wait``
    (:class:`contgrasp_core.holding.HoldSettings`; ``hold`` and ``holding-study``)."""
    p.add_argument("--rate", type=float, default=d.rate, help=f"capacity ramp rate, N/s (default {d.rate:g})")
    p.add_argument("--ramp-time", type=float, default=d.ramp_time,
                   help=f"longest ramp, s (default {d.ramp_time:g}; the largest wrench tried is rate x ramp time)")
    p.add_argument("--contact-wait", type=float, default=d.contact_wait,
                   help=f"longest time without touching the object before the grasp counts as failed, s, from the "
                   f"start or the planned hold's close (default {d.contact_wait:g}; a cage closing from a far base "
                   "needs a few seconds)")


def format_text(out: dict[str, Any]) -> str:
    """The text result: K's eigenvalues, the capacity per direction and its minimum, Q1-Q3 (or
    why the released object was not held)."""
    moved = (f"{1e3 * float(np.hypot(*out['released_displacement'][:2])):.2f} mm / "
             f"{out['released_displacement'][2]:.4f} rad away")
    head = [f"object: {out['object']}, base {out['base']}, law {out['law']}, support {out['support']:g} N/m"]
    tail = [f"Q1 {out['Q1']:.4g}, Q2 {out['Q2']:.4g}, Q3 {out['Q3']:.4g}", f"wall time {out['wall_time_s']:.1f} s"]
    if not out["held"]:
        return "\n".join([*head, f"grasp settled at {out['settle_time_s']:.3f} s; not holding: the released object "
                           f"got away ({out['release_reason']}), {moved}", "capacity_min 0 N", *tail])
    k = np.asarray(out["stiffness"])
    lines = [*head,
             f"grasp settled at {out['settle_time_s']:.3f} s; released object came to rest {moved}",
             "grasp stiffness K (fx, fy, torque by x, y, rotation):",
             *("  " + "  ".join(f"{v:11.4g}" for v in row) for row in k),
             "eigenvalues of its symmetric part, torque and rotation scaled by the object radius (N/m): "
             + ", ".join(f"{v:.4g}" for v in out["stiffness_eigenvalues"]),
             "holding capacity (N, torque / radius) per direction (fx, fy, tau):"]
    for c in out["capacity"]:
        state = "held to the ramp's end: a lower bound" if c["held"] else c["reason"]
        lines.append(f"  ({c['direction'][0]:+.2f}, {c['direction'][1]:+.2f}, {c['direction'][2]:+.0f}): "
                     f"{c['magnitude']:.4g} ({state})")
    bound = " (a lower bound: that direction held to the ramp's end)" if out["capacity_is_bound"] else ""
    lines += [f"capacity_min {out['capacity_min']:.4g} N{bound}", _ceiling_line(out), *tail]
    return "\n".join(lines)


def _ceiling_line(out: dict[str, Any]) -> str:
    """The muscles' ceiling (M5) of the grasp's rest shape, in words."""
    if out["muscles_hold_shape"] is False:
        return "muscle ceiling: the muscles cannot hold this rest shape at all (0 N)"
    top = out["muscle_ceiling_min"]
    return ("muscle ceiling: unbounded muscles (no ceiling)" if top is None
            else f"muscle ceiling of this shape, weakest direction: {top:.4g} N")


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    """The scenario of the command line: the paper's (:data:`~contgrasp_core.scenario.PAPER`)
    around the object, with the rod of ``--nodes``, ``--max-muscle-stress`` and ``--base``, and
    the law and its settings (the object fixed while grasping: the loading releases it)."""
    if not 3 <= args.nodes <= 1001:
        raise InvalidParameterError(f"--nodes must be in [3, 1001], got {args.nodes}")
    obj = object_from_args(args, ROD_SCALE)
    base: dict[str, Any] = {}
    if args.base is not None:
        if not np.all(np.isfinite(args.base)):
            raise InvalidParameterError(f"--base must be three finite numbers, got {args.base}")
        base = {"base_position": (args.base[0], args.base[1]), "base_angle": args.base[2]}
    return PAPER.with_object(obj, rod=rod_from_args(args, **base), law=args.law, hold_law=hold_law_from_args(args))


def settings_from_args(args: argparse.Namespace) -> HoldSettings:
    """How the grasp is loaded: the released object, its support, friction, the ramps and escapes."""
    return HoldSettings(areal_density=args.density, support=args.support, mu=args.mu, rate=args.rate,
                        ramp_time=args.ramp_time, contact_wait=args.contact_wait, directions=args.directions,
                        escape_distance=args.escape_distance, escape_angle=args.escape_angle)


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Measure the holding of one grasp; return the JSON-able result."""
    scenario = scenario_from_args(args)
    settings = settings_from_args(args)
    check_reach(scenario)  # (the holding law's cage must be able to close: refused before simulating)
    rod = scenario.rod
    t0 = time.perf_counter()
    progress = None if args.json else (lambda phase: print(f"contgrasp hold: {phase}", file=sys.stderr, flush=True))
    cage = cage_capacity(scenario, settings.mu).measure if scenario.law in HOLDING_LAWS else None  # (before simulating)
    result = measure_holding(scenario, settings, progress)
    return {"object": scenario.object.text(),
            "base": [float(rod.base_position[0]), float(rod.base_position[1]), float(rod.base_angle)],
            "law": scenario.law, "support": settings.support, "cage_QH": cage, **result.to_dict(),
            "wall_time_s": time.perf_counter() - t0}
