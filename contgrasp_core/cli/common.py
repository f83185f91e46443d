"""Arguments several subcommands share: the object, ``--object NAME[:PARAMS]`` or ``--outline
FILE.csv`` (:class:`contgrasp_core.objects.ObjectSpec`, one syntax everywhere), and how a sweep
runs, ``--executor``, ``--workers``, ``--scheduler`` (:mod:`contgrasp_core.executors`)."""

from __future__ import annotations

import argparse

from ..executors import EXECUTORS
from ..objects import SYNTAX, ObjectScale, ObjectSpec

__all__ = ["add_object_arguments", "object_from_args", "add_executor_arguments", "add_muscle_argument"]


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
