"""Arguments several subcommands share: the object, ``--object NAME[:PARAMS]`` or ``--outline
FILE.csv`` (:class:`contgrasp_core.objects.ObjectSpec`, one syntax everywhere), the parts of a
:class:`~contgrasp_core.scenario.Scenario` ``simulate`` and ``hold`` both set (the rod's size and
muscles, the law), and how a sweep runs, ``--executor``, ``--workers``, ``--scheduler``
(:mod:`contgrasp_core.executors`)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import Any

from ..control.hold_law import LAWS, HoldLawSettings, check_law_settings
from ..executors import EXECUTORS
from ..objects import SYNTAX, ObjectScale, ObjectSpec
from ..rod.model import RodModel
from ..scenario import PAPER

__all__ = ["add_object_arguments", "object_from_args", "add_executor_arguments", "add_muscle_argument",
           "add_law_arguments", "hold_law_from_args", "rod_from_args"]


def add_object_arguments(parser: argparse.ArgumentParser, scale: ObjectScale) -> None:
    """Register ``--object`` and ``--outline`` (mutually exclusive; default: the scale's circle)."""
    defaults = "; ".join(f"{k} {','.join(f'{v:g}' for v in vals)}" for k, vals in scale.defaults.items())
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--object", metavar="NAME[:PARAMS]", default=None,
        help=f"built-in object: {SYNTAX} "
        f"({scale.name}; defaults {defaults}; centre {scale.center[0]:g}, {scale.center[1]:g}), or outline:FILE.csv "
        "(as --outline); the form the command prints as its object. Default: circle")
    group.add_argument("--outline", metavar="FILE.csv", default=None,
                       help=f"your own object: a CSV outline, rows x, y in the same units ({scale.name}), "
                       "closed implicitly")


def add_muscle_argument(parser: argparse.ArgumentParser) -> None:
    """Register ``--max-muscle-stress`` (Pa; the rod's :attr:`~contgrasp_core.rod.RodModel.max_muscle_stress`)."""
    parser.add_argument("--max-muscle-stress", type=float, default=0.0, metavar="PA",
                        help="the muscles' largest stress, Pa: bounds the couple each section of the arm can make "
                        "(docs/rod.md, 'Muscles with limits'; published octopus-arm models use 1e4-1e5); default 0: "
                        "unbounded, the paper's law as printed")


def add_law_arguments(p: argparse.ArgumentParser) -> None:
    """``--law`` and the holding law's parameters (docs/holding.md (H1)-(H6))."""
    d = HoldLawSettings()
    g = p.add_argument_group("the closed loop's law (docs/holding.md, 'A law that holds')")
    g.add_argument("--law", choices=LAWS, default="paper",
                   help="paper: eq. (19) with rho_d = r (default); hold: the reactive law run first on the object "
                   "held fixed, its path of shapes played back as held shapes with a damper (beyond the paper); "
                   "reactive: cage at a clearance, close, hold the shape and squeeze on what the arm senses "
                   "(docs/holding.md)")
    g.add_argument("--clearance", type=float, default=d.clearance,
                   help=f"hold, reactive: the cage's gap to the object, m (default {d.clearance:g})")
    g.add_argument("--close-gap", type=float, default=d.close_gap,
                   help=f"hold, reactive: the gap at which the shape is latched, m, below the clearance (default {d.close_gap:g})")
    g.add_argument("--squeeze", type=float, default=d.squeeze,
                   help=f"hold, reactive: how deep the held shape presses into the object, m (default {d.squeeze:g})")
    g.add_argument("--hold-gain", type=float, default=d.stiffness_gain,
                   help=f"hold, reactive: the held shape's stiffness gain G >= 0 (default {d.stiffness_gain:g})")
    g.add_argument("--depth-gain", type=float, default=d.depth_gain,
                   help="hold, reactive: after the squeeze, regulate the mean sensed contact depth to --squeeze with this "
                   f"integral gain, 1/s >= 0 (docs/holding.md (H7); default {d.depth_gain:g}: off)")
    g.add_argument("--dwell", type=float, default=d.dwell,
                   help="hold, reactive: stay at the close gap this long, s >= 0, and latch the mean curvature over it "
                   f"(docs/holding.md (H8); default {d.dwell:g}: the one sample at which the gap is reached)")
    g.add_argument("--plan-gain", type=float, default=d.plan_gain,
                   help=f"hold: the played-back shapes' stiffness gain G >= 0 (default {d.plan_gain:g})")
    g.add_argument("--plan-damping", type=float, default=d.plan_damping,
                   help="hold: the stiffness D >= 0 of the damper on the arm's deviation from the plan, from the "
                   f"planner's close on (default {d.plan_damping:g}; 0: none)")
    g.add_argument("--plan-damping-time", type=float, default=d.plan_damping_time,
                   help=f"hold: the damper's relaxation time tau, s > 0 (default {d.plan_damping_time:g})")
    g.add_argument("--plan-squeeze", type=float, default=d.plan_squeeze,
                   help="hold, with friction: after the plan, squeeze the object with the largest balanced normal forces that press "
                   "no element in deeper than this fraction of its radius, in [0, 0.3) (docs/holding.md (P2); "
                   f"default {d.plan_squeeze:g}; 0: none)")
    g.add_argument("--plan-squeeze-time", type=float, default=d.plan_squeeze_time,
                   help=f"hold: the squeeze's ramp after the plan, s > 0 (default {d.plan_squeeze_time:g})")


def hold_law_from_args(args: argparse.Namespace) -> HoldLawSettings:
    """The holding law's parameters of the command line, refused with an input error when out of
    range or given to the paper's law, which ignores them (:func:`~contgrasp_core.control.hold_law.check_law_settings`)."""
    settings = HoldLawSettings(clearance=args.clearance, close_gap=args.close_gap, squeeze=args.squeeze,
                               stiffness_gain=args.hold_gain, depth_gain=args.depth_gain, dwell=args.dwell,
                               plan_gain=args.plan_gain, plan_damping=args.plan_damping,
                               plan_damping_time=args.plan_damping_time, plan_squeeze=args.plan_squeeze,
                               plan_squeeze_time=args.plan_squeeze_time)
    check_law_settings(args.law, settings, lambda name: "--hold-gain" if name == "stiffness_gain" else f"--{name.replace('_', '-')}")
    return settings


def rod_from_args(args: argparse.Namespace, **changes: Any) -> RodModel:
    """The scenario's rod (:data:`~contgrasp_core.scenario.PAPER`'s) with ``--nodes`` and
    ``--max-muscle-stress``, and the command's other ``changes``."""
    return replace(PAPER.rod, n_elements=args.nodes - 1, max_muscle_stress=args.max_muscle_stress, **changes)


def object_from_args(args: argparse.Namespace, scale: ObjectScale) -> ObjectSpec:
    """The object the parsed ``--object`` / ``--outline`` name."""
    return ObjectSpec.from_cli(args.object, args.outline, scale)


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    """Register ``--executor``, ``--workers`` and ``--scheduler``: how the sweep's poses run."""
    parser.add_argument("--executor", choices=EXECUTORS, default="processes",
                        help="run the poses one after the other (serial), on a process pool (processes, the default) or "
                        "on a Dask cluster (dask, with --scheduler); the results are the same")
    parser.add_argument("--workers", type=int, default=None, help="process-pool size (default: all cores)")
    parser.add_argument("--scheduler", help="Dask scheduler address tcp://host:port (with --executor dask)")
