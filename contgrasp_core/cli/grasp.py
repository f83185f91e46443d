"""``contgrasp grasp`` and ``contgrasp figures``: optimal grasps (paper Sec. III, Fig. 2).

``grasp`` solves eq. (9) for one object with the paper's settings by default
(arm L = 2 L_o / 3 tapered L/20 -> L/200, rho_d = r(s), alpha_d = pi/2, chi = 10, the
paper's (rho0, alpha0) per object) with the fast solver or the paper's sweep; a result that
is not a solution (not converged, or outside the contact constraints) exits 1 after it is printed.
``figures`` regenerates the three Fig. 2 panels and the three Fig. 3 quality maps (with their
optimum in ``fig3_<object>.json``) into a directory (default docs/figures).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import MAX_NODES
from ..errors import FailedResult, InvalidParameterError, WriteError
from ..objects import FIG2_SCALE, PAPER_OBJECTS, ObjectSpec
from ..outputs import check_output
from .common import add_object_arguments, object_from_args

if TYPE_CHECKING:
    from ..optimal import GraspResult

__all__ = ["add_parsers", "run_grasp", "run_figures", "NoGraspError"]


class NoGraspError(FailedResult):
    """The solver stopped without an optimal grasp: not converged, or its last iterate violates
    the contact constraints of eq. (9) (``contgrasp grasp`` prints its result, then the one error
    line, and exits 1)."""


def add_parsers(subparsers: Any, parents: Sequence[argparse.ArgumentParser] = ()) -> None:
    """Register the ``grasp`` and ``figures`` subcommands (each sets ``func(args) -> dict``)."""
    g = subparsers.add_parser(
        "grasp",
        parents=list(parents),
        help="optimal grasping configuration of eq. (9) (paper Fig. 2)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_object_arguments(g, FIG2_SCALE)
    g.add_argument("--rho0", type=float, default=None,
                   help="initial contact distance (paper value for the Fig. 2 objects, else the object's nominal radius)")
    g.add_argument("--alpha0", type=float, default=None, help="initial contact angle in (0, pi) (paper value; else 1.6)")
    g.add_argument("--s-o0", dest="s_o0", type=float, default=0.0, help="initial shadow point arclength (default 0)")
    g.add_argument("--chi", type=float, default=10.0, help="tracking weight chi > 0 (default 10)")
    g.add_argument("--nodes", type=int, default=500, help="grid nodes along the arm (default 500)")
    g.add_argument("--solver", choices=("fast", "forward-backward"), default="fast", help="fast Newton (default) or the paper's forward-backward sweep")
    g.add_argument("--eta", type=float, default=1e-6, help="sweep step size (paper: 1e-6)")
    g.add_argument("--gradient", choices=("paper", "exact"), default="paper", help="sweep costates (default: paper's eq. (12))")
    g.add_argument("--max-iterations", dest="max_iterations", type=int, default=None,
                   help="iteration limit (default 200 fast, 100000 forward-backward)")
    g.add_argument("--tol", type=float, default=None, help="stopping threshold on max|kappa + p2| (default 1e-9 fast, 1e-6 forward-backward)")
    g.add_argument("--plot", default=None, metavar="FILE", help="save a Fig. 2-style panel (PNG/PDF/SVG)")
    g.set_defaults(func=run_grasp)

    f = subparsers.add_parser(
        "figures",
        parents=list(parents),
        help="regenerate the paper's Fig. 2 (optimal grasps) and Fig. 3 (quality maps) for the three objects",
        description="Regenerate the paper's Fig. 2 (the optimal grasps of the circle, the ellipse and the deformed "
        "circle, fig2_<object>.png) and Fig. 3 (their quality maps, fig3_<object>.png, each metric's optimum in "
        "fig3_<object>.json) into --out.",
    )
    f.add_argument("--out", default="docs/figures", help="output directory (default docs/figures)")
    f.add_argument("--nodes", type=int, default=500, help="grid nodes along the arm (default 500)")
    f.add_argument("--no-maps", action="store_true", help="skip the Fig. 3 quality maps")
    f.add_argument("--psi-steps", type=int, default=48, help="quality-map polar angles (default 48)")
    f.add_argument("--d-steps", type=int, default=11, help="quality-map distances (default 11)")
    f.set_defaults(func=run_figures)


def _solve(args: argparse.Namespace) -> GraspResult:
    from ..optimal import forward_backward, paper_problem, solve

    # every option is checked, also those the chosen solver ignores (a typo is still an error)
    if not (np.isfinite(args.eta) and args.eta > 0.0):
        raise InvalidParameterError(f"--eta must be a finite number > 0, got {args.eta}")
    if args.tol is not None and not (np.isfinite(args.tol) and args.tol > 0.0):
        raise InvalidParameterError(f"--tol must be a finite number > 0, got {args.tol}")
    if args.plot:
        from ..figures.draw import check_figure_path

        check_figure_path(args.plot)
    given = {k: v for k, v in (("rho0", args.rho0), ("alpha0", args.alpha0)) if v is not None}
    problem = paper_problem(object_from_args(args, FIG2_SCALE), nodes=args.nodes, s_o0=args.s_o0, chi=args.chi, **given)
    if args.max_iterations is not None and args.max_iterations < 1:
        raise InvalidParameterError(f"--max-iterations must be >= 1, got {args.max_iterations}")
    if args.solver == "fast":
        kw: dict[str, Any] = {}
        if args.max_iterations is not None:
            kw["max_iterations"] = args.max_iterations
        if args.tol is not None:
            kw["tol"] = args.tol
        return solve(problem, **kw)
    kw = {"eta": args.eta, "gradient": args.gradient}
    if args.max_iterations is not None:
        kw["max_iterations"] = args.max_iterations
    if args.tol is not None:
        kw["tol"] = args.tol
    return forward_backward(problem, **kw)


def run_grasp(args: argparse.Namespace) -> dict[str, Any]:
    """Solve one optimal grasp; returns the JSON-able result (arrays included)."""
    result = _solve(args)
    out = result.to_dict(arrays=True)
    if args.plot:
        from ..figures.grasp import save_grasp_figure

        out["plot"] = str(save_grasp_figure(result, args.plot, title=f"{out['object']} ({result.solver})"))
    if not result.converged:
        raise NoGraspError(f"no optimal grasp: {result.message}", out)
    if not result.constraints.ok:
        c = result.constraints
        raise NoGraspError(f"no optimal grasp: the result leaves the contact constraints of eq. (9) (min rho {c.min_rho:.3g}, "
                           f"alpha in [{c.min_alpha:.3g}, {c.max_alpha:.3g}], min 1 + rho kappa_o {c.min_speed_factor:.3g})", out)
    return out


def run_figures(args: argparse.Namespace) -> dict[str, Any]:
    """Solve the three Fig. 2 problems with the fast solver and save ``fig2_<object>.png``;
    compute the three Fig. 3 quality maps (process executor) and save ``fig3_<object>.png`` with
    ``fig3_<object>.json`` beside it (grid, each metric's optimum, the tie rule's tolerance)."""
    from ..figures.grasp import save_grasp_figure
    from ..optimal import paper_problem, solve
    from ..quality_map import MapSpec

    out_dir = check_output(args.out, "--out", folder=True)
    if not 3 <= args.nodes <= MAX_NODES:
        raise InvalidParameterError(f"--nodes must be in [3, {MAX_NODES}], got {args.nodes}")
    MapSpec(ObjectSpec.parse("circle"), psi_steps=args.psi_steps, d_steps=args.d_steps)  # checks both before any solve
    files: list[str] = []
    summary: dict[str, dict[str, object]] = {}
    for name in PAPER_OBJECTS:
        result = solve(paper_problem(name, nodes=args.nodes))
        path = save_grasp_figure(result, out_dir / f"fig2_{name}.png", title=name)
        files.append(str(path))
        summary[name] = {
            "object": result.to_dict(arrays=False)["object"],
            "cost": result.cost,
            "converged": result.converged,
            "iterations": result.iterations,
            "wall_time_s": result.wall_time,
            "constraints_ok": result.constraints.ok,
        }
    if not args.no_maps:
        from ..figures.quality_map import quality_map_figure
        from ..quality_map import TIE_RTOL, MapSpec, quality_map

        for name in PAPER_OBJECTS:
            qm = quality_map(MapSpec(ObjectSpec.parse(name), psi_steps=args.psi_steps, d_steps=args.d_steps), progress=not args.json)
            path = out_dir / f"fig3_{name}.png"
            quality_map_figure(qm).savefig(path, dpi=110)
            files.append(str(path))
            meta = {"optimum": {m: {k: v for k, v in o.items() if k not in ("x", "y")} for m, o in qm.optimum.items()},
                    "n_valid": int(qm.valid.sum()), "psi_steps": args.psi_steps, "d_steps": args.d_steps,
                    "tie_rtol": TIE_RTOL}
            # what the figure shows, beside it (no timings: the file changes only when the figure does)
            meta_path = path.with_suffix(".json")
            try:
                meta_path.write_text(json.dumps(meta, indent=1) + "\n")
            except OSError as exc:
                raise WriteError(f"cannot write {meta_path}: {exc.strerror or exc}") from exc
            files.append(str(meta_path))
            summary[name]["quality_map"] = {**meta, "wall_time_s": qm.wall_time}
    return {"files": files, "objects": summary, "nodes": args.nodes}
