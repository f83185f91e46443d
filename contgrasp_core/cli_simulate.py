"""``contgrasp simulate``: the closed-loop grasp of paper Sec. V-C on the project's rod engine.

Wire-up (in ``cli.py``): ``cli_simulate.add_parser(sub, [common])``; the parsed namespace has
``func=cli_simulate.run``, which returns the JSON-able result dict (``cli.main`` prints it).
Without ``parents`` the subcommand adds its own ``--json`` flag.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

import numpy as np

from contgrasp_core.boundary import Boundary, circle, deformed_circle, ellipse
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.feedback import closed_loop_kinematics
from contgrasp_core.rod import Obstacle, RodSystem
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, ClosedLoopResult, paper_gains, run_closed_loop
from contgrasp_core.rod.scenario import PAPER_OBJECT_CENTER, PAPER_OBJECT_RADIUS, paper_model

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["add_parser", "run", "summarize", "static_solution", "snapshot_indices", "plot_fig4", "animate"]


def _object(spec: str) -> tuple[Boundary, float]:
    """``circle[:R]``, ``ellipse:a,b`` or ``deformed`` centred at the paper's (8, 8) cm; returns
    the boundary and the radius used by the adaptive mu2 (circle radius or mean radius)."""
    kind, _, arg = spec.partition(":")
    usage = f"--object must be circle[:R], ellipse:a,b or deformed[:R] (metres), got {spec!r}"
    try:
        vals = [float(v) for v in arg.split(",")] if arg else []
    except ValueError:
        raise InvalidParameterError(usage) from None
    if kind in ("circle", "deformed") and len(vals) <= 1:
        r = vals[0] if vals else PAPER_OBJECT_RADIUS
        make = circle if kind == "circle" else deformed_circle
        return make(r, center=PAPER_OBJECT_CENTER), r
    if kind == "ellipse" and len(vals) in (0, 2):
        a, b = vals if vals else (0.03, 0.02)
        return ellipse(a, b, PAPER_OBJECT_CENTER), float(np.sqrt(a * b))
    raise InvalidParameterError(usage)


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser] | None = None) -> argparse.ArgumentParser:
    """Register the ``simulate`` subcommand (``parents`` e.g. the CLI's common ``--json/--debug``)."""
    p = subparsers.add_parser("simulate", help="closed-loop grasp on the Cosserat rod engine (paper Sec. V-C)",
                              description=__doc__.splitlines()[0], parents=parents or [])
    p.add_argument("--object", default="circle", help="circle[:R] | ellipse:a,b | deformed[:R] (m), centre (0.08, 0.08)")
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


def static_solution(res: ClosedLoopResult, obstacle_radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The theoretical static closed loop (eq. rho_alpha_2 with eq. curvature_feedback) from the
    rod's base state, for a circular object: (s, rho, alpha) on the rod nodes."""
    m, g = res.model, res.gains
    s = m.s_nodes
    mu2 = np.asarray(g.mu2, dtype=float)
    mu2_fn = (lambda si: np.interp(si, m.joint_s, mu2)) if mu2.ndim else float(mu2)
    sol = closed_loop_kinematics(float(res.rho[-1][0]), float(res.alpha[-1][0]), s, g.mu1, mu2_fn,
                                 1.0 / obstacle_radius, length_unit=g.length_unit)
    return s, sol.rho, sol.alpha


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


def _draw_arm(ax: Axes, x: np.ndarray, r: np.ndarray, **kw: Any) -> None:
    t = np.gradient(x, axis=0)
    t /= np.hypot(t[:, 0], t[:, 1])[:, None]
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    outline = np.concatenate([x + r[:, None] * nrm, (x - r[:, None] * nrm)[::-1]])
    ax.fill(outline[:, 0] * 100, outline[:, 1] * 100, **kw)


def snapshot_indices(res: ClosedLoopResult, count: int = 6) -> np.ndarray:
    """Record indices at equal fractions of the tip's travelled path (the motion is fast early and
    slow late, so equal time spacing would bunch the snapshots)."""
    tip = res.x[:, -1]
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(tip, axis=0).T))])
    targets = np.linspace(0.0, path[-1], count)
    idx = np.searchsorted(path, targets).clip(0, len(path) - 1)
    idx[-1] = len(path) - 1
    return np.unique(idx)


def plot_fig4(res: ClosedLoopResult, boundary: Boundary, path: str, obstacle_radius: float | None = None) -> None:
    """Paper Fig. 4: six snapshots of the arm (with its radius) around the object; rho/rho_d and
    alpha along s at several times, the static solution of eq. curvature_feedback dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = res.model
    r = m.radius(m.s_nodes)
    fig = plt.figure(figsize=(7.0, 7.5))
    ax0 = fig.add_subplot(2, 1, 1)
    idx = snapshot_indices(res, 6)
    _, pts = boundary.sample(400)
    ax0.fill(pts[:, 0] * 100, pts[:, 1] * 100, color="0.75", zorder=1)
    for j, k in enumerate(idx):
        _draw_arm(ax0, res.x[k], r, color="purple", alpha=0.15 + 0.12 * j, lw=0, zorder=2)
        ax0.annotate(f"{res.t[k]:.2f} s", res.x[k][-1] * 100, fontsize=7, color="purple")
    ax0.plot(0, 0, "ks", ms=5)
    ax0.set_aspect("equal")
    ax0.set_xlabel("x [cm]")
    ax0.set_ylabel("y [cm]")
    ax0.set_title("closed-loop grasp (eq. dynamic_feedback), six time instances")
    ax1 = fig.add_subplot(2, 2, 3)
    ax2 = fig.add_subplot(2, 2, 4)
    s_n = m.s_nodes / m.length
    cmap = plt.get_cmap("Blues")
    for j, k in enumerate(idx[1:]):
        c = cmap(0.35 + 0.65 * (j + 1) / len(idx))
        ax1.plot(s_n, res.rho[k] / r, color=c, lw=1.2, label=f"{res.t[k]:.2f} s")
        ax2.plot(s_n, res.alpha[k], color=c, lw=1.2)
    if obstacle_radius is not None:
        s, rho_s, alpha_s = static_solution(res, obstacle_radius)
        ax1.plot(s / m.length, rho_s / r, "k--", lw=1.2, label="static theory")
        ax2.plot(s / m.length, alpha_s, "k--", lw=1.2)
    ax1.axhline(1.0, color="0.6", lw=0.6)
    ax2.axhline(0.5 * np.pi, color="0.6", lw=0.6)
    ax1.set_ylim(0, 3)
    ax2.set_ylim(0, np.pi)
    ax1.set_xlabel("s / L")
    ax2.set_xlabel("s / L")
    ax1.set_ylabel(r"$\rho / \rho_d$")
    ax2.set_ylabel(r"$\alpha$ [rad]")
    ax1.legend(fontsize=6)
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=150)
    except (OSError, ValueError) as exc:
        raise InvalidParameterError(f"cannot write the figure {path}: {exc}") from exc
    finally:
        plt.close(fig)


def animate(res: ClosedLoopResult, boundary: Boundary, path: str, frames: int = 60) -> None:
    """GIF of the arm (with its radius) wrapping the object."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    m = res.model
    r = m.radius(m.s_nodes)
    idx = snapshot_indices(res, frames)
    _, pts = boundary.sample(400)
    fig, ax = plt.subplots(figsize=(4, 4))

    def draw(k: int) -> None:
        ax.clear()
        ax.fill(pts[:, 0] * 100, pts[:, 1] * 100, color="0.75")
        _draw_arm(ax, res.x[k], r, color="purple", alpha=0.7, lw=0)
        ax.set_xlim(-2, 22)
        ax.set_ylim(-6, 14)
        ax.set_aspect("equal")
        ax.set_title(f"t = {res.t[k]:.2f} s")
        ax.set_xlabel("x [cm]")

    anim = FuncAnimation(fig, draw, frames=idx)
    try:
        anim.save(path, writer=PillowWriter(fps=12))
    except (OSError, ValueError) as exc:
        raise InvalidParameterError(f"cannot write the animation {path}: {exc}") from exc
    finally:
        plt.close(fig)


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
        from contgrasp_core.plots import check_figure_path

        check_figure_path(args.plot)
    if args.animate:
        _check_animation_path(args.animate)
    boundary, r_obj = _object(args.object)
    overrides = {} if args.damping is None else {"damping": args.damping}
    model = paper_model(n_elements=args.nodes - 1, **overrides)
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
