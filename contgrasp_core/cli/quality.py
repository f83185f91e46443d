"""``contgrasp quality-map``: grasp quality over arm base poses (paper Sec. IV-C, Fig. 3)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ..errors import InvalidParameterError, output_error, refuse_ignored
from ..outputs import check_output
from ..objects import FIG2_SCALE
from ..quality_map import METRICS, MapSpec, load_map, map_paths, quality_map, save_map
from .common import add_executor_arguments, add_object_arguments, object_from_args

__all__ = ["add_parser", "run"]

COMPUTING_OPTIONS = ("--object", "--outline", "--psi-steps", "--d-steps", "--d-min", "--d-max", "--nodes", "--contact-tol",
                     "--executor", "--workers", "--scheduler", "--no-optimise", "--out")
"""The options of a map computed anew: ``--load`` refuses them (a saved map is shown as it was computed)."""


def _dest(option: str) -> str:
    return option[2:].replace("-", "_")


def add_parser(sub: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Register the ``quality-map`` subcommand."""
    p = sub.add_parser(
        "quality-map",
        parents=parents,
        help="grasp quality Q1..Q3 over base poses in the disc region D, with Nelder-Mead maxima (Fig. 3)",
        description=__doc__,
    )
    add_object_arguments(p, FIG2_SCALE)
    p.add_argument("--psi-steps", type=int, default=24, help="polar angles of the base (default 24)")
    p.add_argument("--d-steps", type=int, default=6, help="distances in [d_min, d_max] (default 6)")
    p.add_argument("--d-min", type=float, default=3.0,
                   help="nearest base distance from the object, paper units (default 3)")
    p.add_argument("--d-max", type=float, default=13.0,
                   help="farthest base distance, paper units, below the arm length (half the object's perimeter; default 13)")
    p.add_argument("--nodes", type=int, default=200, help="inner optimal-grasp grid nodes (default 200)")
    p.add_argument("--contact-tol", type=float, default=0.05, help="contact where delta >= -tol (default 0.05)")
    p.add_argument("--metric", choices=(*METRICS, "all"), default="all", help="metric(s) to maximise and plot")
    add_executor_arguments(p)
    p.add_argument("--no-optimise", action="store_true", help="skip the Nelder-Mead maximisation")
    p.add_argument("--out", metavar="FILE", help="save the map (FILE.npz + FILE.json; FILE.npz or FILE.json name the same "
                   "pair, any other suffix is kept: egg.csv -> egg.csv.npz) for later re-plotting")
    p.add_argument("--load", metavar="FILE", help="re-plot / report a saved map (FILE as --out named it) instead of computing")
    p.add_argument("--plot", metavar="FILE", help="draw the Fig. 3 panels to FILE")
    p.set_defaults(func=run, format_text=format_text,
                   computing_defaults={option: p.get_default(_dest(option)) for option in COMPUTING_OPTIONS})


def format_text(out: dict[str, Any]) -> str:
    """The text result (without --json): the map's size and validity, then per metric its
    optimum (value, base pose (psi, d) and the base's position and heading) and the best grid
    pose with all three Q there; the grids themselves are in --json only."""
    n_psi, n_d = len(out["psi"]), len(out["d"])
    lines = [
        f"object: {out['object']}",
        f"grid: {n_psi} polar angles x {n_d} distances in [{out['d'][0]:g}, {out['d'][-1]:g}]; "
        f"{out['n_valid']} of {n_psi * n_d} poses valid" + (f" (invalid: {', '.join(out['invalid_reasons'])})" if out["invalid_reasons"] else ""),
    ]
    for metric, opt in out["optimum"].items():
        grid = np.asarray(out[metric], dtype=float) if metric in out else None
        if grid is not None and np.isfinite(grid).any():
            i, j = np.unravel_index(np.nanargmax(grid), grid.shape)
            at = ", ".join(f"{m} {float(np.asarray(out[m], dtype=float)[i, j]):.6g}" for m in METRICS)
            best_grid = f"\n  best grid pose psi {out['psi'][i]:.4g} rad, d {out['d'][j]:.4g}: {at}"
        else:
            best_grid = ""
        if not opt:
            lines.append(f"optimum {metric}: none (no valid pose){best_grid}")
            continue
        base = opt.get("base", {})
        lines.append(
            f"optimum {metric}: {opt['value']:.6g} at psi {opt['psi']:.4g} rad, d {opt['d']:.4g} "
            f"(base x {base.get('x', float('nan')):.4g}, y {base.get('y', float('nan')):.4g}, "
            f"heading {base.get('theta', float('nan')):.4g} rad; {opt.get('evaluations', '?')} evaluations){best_grid}"
        )
    if not out["optimum"]:
        lines.append("optimum: none (no valid pose)" if not out["n_valid"] else "optimum: not computed (--no-optimise)")
    lines.append(f"wall_time_s: {out['wall_time_s']:.3g} ({out['n_solves']} solves, executor {out['executor']})")
    if out.get("saved"):  # (save_map writes the arrays and the metadata beside them)
        lines.append("saved: {} and {}".format(*map_paths(out["saved"])))
    if out.get("plot"):
        lines.append(f"plot: {out['plot']}")
    lines.append("(in --json only: psi, d, Q1, Q2, Q3, valid, optimum arm shapes, spec)")
    return "\n".join(lines)


def _check_out_path(path: str) -> None:
    """``--out FILE``: FILE.npz and FILE.json must be creatable (checked before computing)."""
    for f in map_paths(path):
        check_output(f, "--out")


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Execute ``contgrasp quality-map``; JSON keys in docs/cli.md."""
    if args.load:
        refuse_ignored([o for o, default in args.computing_defaults.items() if getattr(args, _dest(o)) != default],
                       "with --load (a saved map is shown as it was computed)", "a map computed anew (no --load)")
    if args.plot:
        from ..figures.draw import check_figure_path

        check_figure_path(args.plot)
    if args.out:
        _check_out_path(args.out)
    if args.load:
        qm = load_map(args.load)
    else:
        if args.executor == "dask" and not args.scheduler:
            raise InvalidParameterError("--executor dask needs --scheduler tcp://host:port")
        if args.workers is not None and args.workers < 1:
            raise InvalidParameterError("--workers must be >= 1")
        spec = MapSpec(
            object=object_from_args(args, FIG2_SCALE), psi_steps=args.psi_steps, d_steps=args.d_steps, d_min=args.d_min,
            d_max=args.d_max, nodes=args.nodes, contact_tol=args.contact_tol,
        )
        qm = quality_map(
            spec, executor=args.executor, workers=args.workers, scheduler=args.scheduler,
            progress=not args.json, optimise=not args.no_optimise,
        )
        if args.out:
            save_map(qm, args.out)
    out = qm.to_dict()
    if args.metric != "all" and out["optimum"]:
        out["optimum"] = {args.metric: out["optimum"].get(args.metric)}
    if args.plot:
        from ..figures.quality_map import quality_map_figure

        fig = quality_map_figure(qm)
        try:
            fig.savefig(args.plot, dpi=120)
        except (OSError, ValueError) as exc:
            raise output_error(f"the figure {args.plot}", exc) from exc
        out["plot"] = args.plot
    out["saved"] = args.out
    return out
