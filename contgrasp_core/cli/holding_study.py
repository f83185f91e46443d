"""``contgrasp holding-study``: do Q1-Q3 predict how firmly a grasp holds? (beyond the paper)

For every base pose of the object's quality map (paper Sec. IV-C) and each metric's optimum:
the static Q1-Q3, then the rod's closed-loop grasp from that pose with its settled Q1-Q3, grasp
stiffness and holding capacity (:mod:`contgrasp_core.holding.study`); Spearman correlations
with bootstrap intervals. Results go to ``--out FILE.jsonl`` as they arrive; running the same
command again resumes. The arguments make the study's :class:`~contgrasp_core.holding.study.StudySpec`
(:func:`spec_from_args`, what the results file records), which makes each pose's
:class:`~contgrasp_core.scenario.Scenario` (:func:`contgrasp_core.holding.study.pose_scenario`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from collections import Counter
from typing import Any

import numpy as np

from ..errors import InvalidParameterError
from ..control.hold_law import LAWS
from .hold import add_ramp_arguments
from ..holding.study import ARMS, PREDICTORS, RESPONSES, StudySpec, correlations, expand_symmetric, run_study
from ..objects import FIG2_SCALE
from ..outputs import check_output
from .common import add_executor_arguments, add_muscle_argument, add_object_arguments, object_from_args

__all__ = ["add_parser", "run", "format_text", "spec_from_args"]


def add_parser(sub: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Register the ``holding-study`` subcommand."""
    d = StudySpec()
    p = sub.add_parser("holding-study", parents=parents, description=__doc__.splitlines()[0],
                       help="Q1-Q3 against measured grasp stiffness and holding capacity over a quality map's poses")
    add_object_arguments(p, FIG2_SCALE)  # (an outline about an origin inside it: the rod's is scaled about it)
    p.add_argument("--psi-steps", type=int, default=d.psi_steps, help=f"polar angles (default {d.psi_steps})")
    p.add_argument("--d-steps", type=int, default=d.d_steps, help=f"distances (default {d.d_steps})")
    p.add_argument("--d-min", type=float, default=d.d_min,
                   help=f"nearest base distance from the object, paper units (default {d.d_min:g})")
    p.add_argument("--d-max", type=float, default=d.d_max,
                   help=f"farthest base distance, paper units, below the arm length (half the object's perimeter; "
                   f"default {d.d_max:g})")
    p.add_argument("--nodes", type=int, default=d.nodes, help=f"rod nodes (default {d.nodes})")
    p.add_argument("--duration", type=float, default=d.duration,
                   help=f"longest closed-loop grasp before a pose counts as not settled, s (default {d.duration:g})")
    p.add_argument("--law", choices=LAWS, default=d.law,
                   help="the closed loop's law: paper (eq. (19)), hold (the planned hold, docs/holding.md (P1)) or "
                   "reactive (its planner, the holding law (H1)-(H8) on what the arm senses)")
    p.add_argument("--depth-gain", type=float, default=d.depth_gain,
                   help="with --law hold or reactive: regulate the mean sensed contact depth to the squeeze after it, integral "
                   f"gain 1/s >= 0 (docs/holding.md (H7); default {d.depth_gain:g}: off)")
    p.add_argument("--dwell", type=float, default=d.dwell,
                   help="with --law hold or reactive: stay at the close gap this long, s >= 0, and latch the mean curvature over "
                   f"it (docs/holding.md (H8); default {d.dwell:g}: one sample)")
    add_muscle_argument(p)
    p.add_argument("--support", type=float, default=d.hold.support,
                   help=f"support stiffness under the released object, N/m (default {d.hold.support:g}; 0: entirely free)")
    p.add_argument("--length-fraction", type=float, default=d.length_fraction,
                   help=f"arm length over the object's perimeter, the map's and the rod's (default {d.length_fraction:g}, "
                   "the paper's map; the holding law closes only past a half-turn wrap)")
    p.add_argument("--arm", choices=ARMS, default=d.arm,
                   help="map: uniform, --length-fraction of the perimeter (the paper's map; default); rod: the rod "
                   "scenario's tapered arm, for the map and the rod alike")
    p.add_argument("--directions", type=int, default=d.hold.directions,
                   help=f"force directions of the capacity ramps, plus two torques (default {d.hold.directions})")
    add_ramp_arguments(p, d.hold)
    p.add_argument("--out", required=True, metavar="FILE.jsonl", help="results, one pose per line (resumed if present)")
    add_executor_arguments(p)
    p.add_argument("--plot", metavar="FILE", help="the static quality map beside the measured stiffness and capacity")
    p.set_defaults(func=run, format_text=format_text)


def format_text(out: dict[str, Any]) -> str:
    """The poses' outcome and the correlation table."""
    outcomes = ", ".join(f"{k} {v}" for k, v in out["outcomes"].items())
    lines = [f"object {out['object']}: {out['poses']} poses measured ({outcomes}), {out['grid_poses']} grid poses "
             f"with their symmetric copies; results in {out['out']}",
             "Spearman rho [95 % bootstrap interval] (n poses):",
             f"{'':12s}" + "".join(f"{r:>28s}" for r in RESPONSES)]
    for pred in PREDICTORS:
        cells = []
        for resp in RESPONSES:
            c = out["correlations"][pred][resp]
            cells.append(f"{c['rho']:+.2f} [{c['low']:+.2f}, {c['high']:+.2f}] ({c['n']})" if np.isfinite(c["rho"])
                         else f"- ({c['n']})")
        lines.append(f"{pred:12s}" + "".join(f"{c:>28s}" for c in cells))
    return "\n".join(lines)


def spec_from_args(args: argparse.Namespace) -> StudySpec:
    """The study of the command line: the object and map grid, the rod's nodes and muscles, the
    law, how long a grasp may take and how each is loaded; every pose's scenario follows from it
    (:func:`contgrasp_core.holding.study.pose_scenario`)."""
    return StudySpec(object=object_from_args(args, FIG2_SCALE).text(), psi_steps=args.psi_steps, d_steps=args.d_steps,
                     d_min=args.d_min, d_max=args.d_max, nodes=args.nodes, duration=args.duration, law=args.law,
                     length_fraction=args.length_fraction, arm=args.arm, depth_gain=args.depth_gain, dwell=args.dwell,
                     max_muscle_stress=args.max_muscle_stress,
                     hold=replace(StudySpec().hold, directions=args.directions, support=args.support, rate=args.rate,
                                  ramp_time=args.ramp_time, contact_wait=args.contact_wait))


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run (or resume) the study; return the JSON-able summary."""
    if args.workers is not None and args.workers < 1:
        raise InvalidParameterError(f"--workers must be >= 1, got {args.workers}")
    check_output(args.out, "--out")
    if args.plot:
        from ..figures.draw import check_figure_path

        check_figure_path(args.plot)
    spec = spec_from_args(args)
    qm, rows = run_study(spec, args.out, executor=args.executor, workers=args.workers, scheduler=args.scheduler,
                         progress=not args.json)
    ok = [r for r in rows if r.get("status") == "ok"]
    changed = sum(bool(r.get("map_changed")) for r in rows)
    if changed:
        print(f"contgrasp holding-study: warning: {changed} of the {len(rows)} poses in {args.out} were measured with "
              "another static map (their base or static Q1-Q3 differ from today's, or the pose is no longer valid in "
              "it); the correlations use today's map", file=sys.stderr)
    full = expand_symmetric(spec, rows)
    out = {"object": qm.spec.object.text(), "out": args.out, "poses": len(rows), "grasped": len(ok),
           "not_grasped": len(rows) - len(ok), "outcomes": dict(Counter(r.get("outcome", "?") for r in rows)),
           "map_changed": changed, "distinct_rows": spec.distinct_rows(), "grid_poses": sum(r["key"].startswith("grid:") for r in full),
           "correlations": correlations(rows), "correlations_with_optima": correlations(rows, grid_only=False)}
    if args.plot:
        from ..figures.holding import plot_study

        out["plot"] = str(plot_study(qm, full, args.plot))
    return out
