"""``contgrasp simulate``: the closed-loop grasp of paper Sec. V-C on the project's rod engine.

Wire-up (in ``cli/__init__.py``): ``simulate.add_parser(sub, [common])``; the parsed namespace has
``func=simulate.run``, which returns the JSON-able result dict (``cli.main`` prints it).
Without ``parents`` the subcommand adds its own ``--json`` flag.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import Any

import numpy as np

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.control import paper_gains
from contgrasp_core.figures.closed_loop import animate, plot_fig4
from contgrasp_core.rod import Obstacle, RodSystem
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, ClosedLoopResult, run_closed_loop
from contgrasp_core.objects import ROD_SCALE
from contgrasp_core.scenario import PAPER

from .common import add_object_arguments, object_from_args

__all__ = ["add_parser", "run", "summarize"]


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser] | None = None) -> argparse.ArgumentParser:
    """Register the ``simulate`` subcommand (``parents`` e.g. the CLI's common ``--json/--debug``)."""
    p = subparsers.add_parser("simulate", help="closed-loop grasp on the Cosserat rod engine (paper Sec. V-C)",
                              description=__doc__.splitlines()[0], parents=parents or [])
    add_object_arguments(p, ROD_SCALE)
    p.add_argument("--duration", type=float, default=10.0, help="max simulated time, s (stops earlier when settled)")
    p.add_argument("--control-period", type=float, default=None,
                   help="sample-and-hold period of the feedback, s (default: continuous implicit feedback)")
    p.add_argument("--dt", type=float, default=0.01, help="largest integrator step, s")
    p.add_argument("--nodes", type=int, default=101, help="rod nodes (elements + 1)")
    p.add_argument("--damping", type=float, default=None, help="damping zeta, 1/s (default: scenario value)")
    p.add_argument("--contact-tol", type=float, default=0.5,
                   help="contact region for the statistics: delta >= -tol * r(s) (fraction of the local radius)")
    if not parents:
        p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", metavar="FILE", help="write the paper's Fig. 4 (PNG/PDF/SVG)")
    p.add_argument("--animate", metavar="FILE.gif", help="write an animation of the grasp")
    p.set_defaults(func=run)
    return p


def summarize(res: ClosedLoopResult, contact_tol: float = 0.5) -> dict[str, Any]:
    """The JSON result: final shape and contact state along s, settle data, penetration and the
    contact-region statistics of rho/rho_d (rho_d = r(s)) and alpha."""
    m = res.model
    r = m.radius(m.s_nodes)
    rho, alpha = res.rho[-1], res.alpha[-1]
    contact = (r - rho) >= -contact_tol * r
    def stat(v: np.ndarray) -> float | None:
        return float(np.mean(v[contact])) if np.any(contact) else None
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
        "max_penetration": float(res.penetration.max()),
        "max_penetration_ratio": float(res.penetration_ratio.max()),
        "final_penetration": float(res.penetration[-1]),
        "final_penetration_ratio": float(res.penetration_ratio[-1]),
        "contact_nodes": int(np.sum(contact)),
        "contact_tol_ratio": float(contact_tol),
        "mean_abs_rho_ratio_minus_1_contact": stat(np.abs(rho / r - 1.0)),
        "mean_abs_alpha_minus_half_pi_contact": stat(np.abs(alpha - 0.5 * np.pi)),
        "damping_per_s": m.damping,
        "control": "continuous" if res.config.control_period is None else f"zoh {res.config.control_period} s",
    }


MAX_NODES = 10_001
"""Largest rod the command accepts (the paper's arm has 101 nodes)."""


def _check_animation_path(path: str) -> None:
    from pathlib import Path

    from PIL import Image

    p = Path(path)
    fmt = Image.registered_extensions().get(p.suffix.lower())
    if fmt not in ("GIF", "WEBP", "PNG"):
        raise InvalidParameterError(f"--animate {path}: use a .gif, .webp or .png file name")
    if p.is_dir() or (p.parent.exists() and not p.parent.is_dir()):
        raise InvalidParameterError(f"--animate {path}: not a writable file name")


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the scenario; write the plot/animation if asked; return the JSON-able result."""
    if not 3 <= args.nodes <= MAX_NODES:
        raise InvalidParameterError(f"--nodes must be in [3, {MAX_NODES}], got {args.nodes}")
    if not (np.isfinite(args.contact_tol) and args.contact_tol >= 0.0):
        raise InvalidParameterError(f"--contact-tol must be a finite number >= 0, got {args.contact_tol}")
    if not (np.isfinite(args.dt) and args.dt > 0.0):  # checked also when --control-period makes it unused
        raise InvalidParameterError(f"--dt must be a finite number > 0, got {args.dt}")
    if args.plot:
        from contgrasp_core.figures.draw import check_figure_path

        check_figure_path(args.plot)
    if args.animate:
        _check_animation_path(args.animate)
    obj = object_from_args(args, ROD_SCALE)
    boundary, r_obj = obj.boundary(), obj.radius
    overrides = {} if args.damping is None else {"damping": args.damping}
    model = replace(PAPER.rod, n_elements=args.nodes - 1, **overrides)
    cfg = ClosedLoopConfig(duration=args.duration, control_period=args.control_period,
                           dt=args.dt if args.control_period is None else None,
                           record_period=0.01)
    res = run_closed_loop(RodSystem(model, Obstacle(boundary)), paper_gains(model, r_obj), cfg)
    out = summarize(res, args.contact_tol)
    if args.plot:
        plot_fig4(res, boundary, args.plot, r_obj if boundary.kind == "circle" else None)
    if args.animate:
        animate(res, boundary, args.animate)
    return out
