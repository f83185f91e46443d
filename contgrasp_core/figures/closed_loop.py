"""Fig. 4 of the paper: the closed-loop grasp on the rod engine (snapshots, rho/rho_d and alpha
along the arm against the static solution) and its animation.

The static solution (eq. (20) integrated through eq. (8) from the base's contact state) is the
equilibrium of the feedback law *without* the object: it ignores contact, so it may dip below
rho = rho_d, into the object, where the real rod is held at the surface (docs/rod.md)."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..boundary import Boundary
from ..errors import output_error
from ..rod.closed_loop import ClosedLoopResult, static_solution
from .draw import save

__all__ = ["snapshot_indices", "snapshot_colours", "plane_axes", "finish_profile_panels", "fig4_figure", "plot_fig4", "animate",
           "data_limits", "ratio_axis", "STATIC_LABEL", "SNAPSHOT_CMAP", "LENGTH_UNIT", "LAW_TITLES"]

SNAPSHOT_CMAP = "turbo"
"""Colour map of the arm snapshots (and their rho, alpha curves) in Fig. 4, its animation and the
run figure of the ROS graph: ordered in time, successive snapshots distinguishable."""
LENGTH_UNIT = "m"
"""Length unit of the plane (x, y) axes of Fig. 4, its animation and the run figure."""
LAW_TITLES = {"paper": "feedback law eq. (19)", "hold": "planned hold, docs/holding.md",
              "reactive": "reactive holding law, docs/holding.md"}
"""How a figure's title names the law that ran (:data:`~contgrasp_core.control.hold_law.LAWS`)."""


def snapshot_colours(count: int) -> np.ndarray:
    """``count`` RGBA colours of :data:`SNAPSHOT_CMAP` for successive snapshots, earliest first:
    evenly spaced over 0.05 (dark blue) .. 0.95 (dark red) of the map, so neighbours differ in
    hue, not only in lightness (a one-hue map such as Purples made late snapshots, drawn
    translucent and overlapping, look alike), and the final one is red (six snapshots: >= 0.47
    apart in RGB; the map's near-black ends are left out)."""
    return colormaps[SNAPSHOT_CMAP](np.linspace(0.05, 0.95, count) if count > 1 else [0.95])


def plane_axes(ax: Axes) -> None:
    """Equal aspect and x, y labels in :data:`LENGTH_UNIT` (Fig. 4, its animation, the run figure)."""
    ax.set_aspect("equal")
    ax.set_xlabel(f"x [{LENGTH_UNIT}]")
    ax.set_ylabel(f"y [{LENGTH_UNIT}]")


def _draw_arm(ax: Axes, x: np.ndarray, r: np.ndarray, **kw: Any) -> None:
    t = np.gradient(x, axis=0)
    t /= np.hypot(t[:, 0], t[:, 1])[:, None]
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    outline = np.concatenate([x + r[:, None] * nrm, (x - r[:, None] * nrm)[::-1]])
    ax.fill(outline[:, 0], outline[:, 1], **kw)


def snapshot_indices(res: ClosedLoopResult, count: int = 6) -> np.ndarray:
    """Record indices at equal fractions of the tip's travelled path (the motion is fast early and
    slow late, so equal time spacing would bunch the snapshots)."""
    tip = res.x[:, -1]
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(tip, axis=0).T))])
    targets = np.linspace(0.0, path[-1], count)
    idx = np.searchsorted(path, targets).clip(0, len(path) - 1)
    idx[-1] = len(path) - 1
    return np.unique(idx)


STATIC_LABEL = "static solution, eq. (20)\n(equilibrium of the law without the object)"
"""Legend entry of the static solution: it ignores contact, so it may cut into the object (docs/rod.md)."""


def data_limits(values: list[np.ndarray], *, log: bool = False, pad: float = 0.05,
                include: tuple[float, ...] = ()) -> tuple[float, float]:
    """Axis limits that show every value of every curve (and the ``include`` levels), padded by
    ``pad`` of the span (of the log span when ``log``)."""
    v = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in values] + [np.asarray(include, dtype=float)])
    v = v[np.isfinite(v) & (v > 0.0)] if log else v[np.isfinite(v)]
    lo, hi = float(v.min()), float(v.max())
    if log:
        span = max(np.log10(hi / lo), 0.1)
        return lo / 10.0 ** (pad * span), hi * 10.0 ** (pad * span)
    span = max(hi - lo, 1e-12)
    return lo - pad * span, hi + pad * span


def ratio_axis(ax: Axes, ratios: list[np.ndarray]) -> None:
    """rho/rho_d on a log scale (it spans ~0.6 to ~100 during a grasp) with limits from the data
    and the target 1 included; linear when some value is not positive (a centreline inside the
    object), which a log axis could not show."""
    positive = all(np.all(np.asarray(v)[np.isfinite(v)] > 0.0) for v in ratios)
    if positive:
        ax.set_yscale("log")
    ax.set_ylim(*data_limits(ratios, log=positive, include=(1.0,)))
    ax.set_ylabel(r"$\rho / \rho_d$ [-]" + ("  (log scale; " if positive else "  (") + r"$\rho_d = r(s)$)")


def finish_profile_panels(ax_r: Axes, ax_a: Axes, ratios: list[np.ndarray], alphas: list[np.ndarray], legend_on: Any,
                          *, ncols: int, fontsize: float) -> None:
    """The rho/rho_d and alpha panels along the arm (Fig. 4 and the run figure): the targets
    rho = rho_d and alpha = pi/2 of the law (grey dotted: no snapshot colour), limits that show every curve, labels, and one legend
    (the curves' labels and the alpha target) at the bottom of ``legend_on`` (a figure)."""
    ax_r.axhline(1.0, color="0.35", lw=1.0, ls=":", label=r"target $\rho = \rho_d$")
    ax_a.axhline(0.5 * np.pi, color="0.35", lw=1.0, ls=":", label=r"target $\alpha = \pi/2$")
    ratio_axis(ax_r, ratios)
    ax_a.set_ylim(*data_limits(alphas, include=(0.0, np.pi)))
    for ax in (ax_r, ax_a):
        ax.set_xlabel("s / L [-]  (along the arm)")
        ax.grid(alpha=0.3)
    ax_a.set_ylabel(r"$\alpha$ [rad]")
    handles, labels = ax_r.get_legend_handles_labels()
    h2, l2 = ax_a.get_legend_handles_labels()
    legend_on.legend(handles + h2[-1:], labels + l2[-1:], loc="outside lower center", ncols=ncols, fontsize=fontsize)


def fig4_figure(res: ClosedLoopResult, boundary: Boundary, obstacle_radius: float | None = None) -> Figure:
    """Paper Fig. 4 as a :class:`~matplotlib.figure.Figure`: six snapshots of the arm (with its
    radius) around the object, coloured by simulated time (:func:`snapshot_colours`, legend); a
    movable object filled where it started and outlined where it is at each snapshot, in the
    snapshot's colour; rho/rho_d (log scale, limits
    from the data, so every curve shows) and alpha along s at the same times, with the targets
    rho = rho_d and alpha = pi/2 and, for a circle, the static solution of eq. (20) dashed.
    The title names the law that ran."""
    m = res.model
    r = m.radius(m.s_nodes)
    fig = Figure(figsize=(8.0, 9.0), layout="constrained")
    grid = fig.add_gridspec(2, 1, height_ratios=(1.0, 1.1))
    top, bottom = fig.add_subfigure(grid[0]), fig.add_subfigure(grid[1])
    ax0 = top.add_subplot(1, 1, 1)
    idx = snapshot_indices(res, 6)
    _, pts = boundary.sample(400)
    moving = res.object_q is not None
    ax0.fill(pts[:, 0], pts[:, 1], color="0.75", zorder=1, label="object at the start" if moving else "object")
    colours = snapshot_colours(len(idx))
    for colour, k in zip(colours, idx, strict=True):
        _draw_arm(ax0, res.x[k], r, color=colour, alpha=0.6, lw=0, zorder=2, label=f"t = {res.t[k]:.2f} s")
        if moving:  # (the object where it is then: the arm wraps it there, not where it started)
            moved = res.object_at(k, np.vstack([pts, pts[:1]]))
            ax0.plot(moved[:, 0], moved[:, 1], color=colour, lw=1.2, ls="--", zorder=3)
    ax0.plot(0, 0, "ks", ms=5, label="base (clamped)")
    plane_axes(ax0)
    ax0.legend(title="arm (and object, dashed) at simulated time" if moving else "arm at simulated time", fontsize=7,
               title_fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax0.set_title(f"closed-loop grasp ({LAW_TITLES[res.law]}), six time instances")
    ax1, ax2 = bottom.subplots(1, 2)
    s_n = m.s_nodes / m.length
    ratios, alphas = [], []
    for c, k in zip(colours, idx, strict=True):
        ratios.append(res.rho[k] / r)
        alphas.append(res.alpha[k])
        ax1.plot(s_n, ratios[-1], color=c, lw=1.2, label=f"t = {res.t[k]:.2f} s")
        ax2.plot(s_n, alphas[-1], color=c, lw=1.2, label=f"t = {res.t[k]:.2f} s")
    if obstacle_radius is not None:
        s, rho_s, alpha_s = static_solution(res, obstacle_radius)
        ratios.append(rho_s / r)
        alphas.append(alpha_s)
        ax1.plot(s / m.length, rho_s / r, "k--", lw=1.2, label=STATIC_LABEL)
        ax2.plot(s / m.length, alpha_s, "k--", lw=1.2, label=STATIC_LABEL)
    finish_profile_panels(ax1, ax2, ratios, alphas, bottom, ncols=3, fontsize=7)
    return fig


def plot_fig4(res: ClosedLoopResult, boundary: Boundary, path: str, obstacle_radius: float | None = None) -> None:
    """Write :func:`fig4_figure` to ``path`` (format from the suffix)."""
    save(fig4_figure(res, boundary, obstacle_radius), path, dpi=150)


def animate(res: ClosedLoopResult, boundary: Boundary, path: str, frames: int = 60) -> None:
    """GIF of the arm (with its radius) wrapping the object (where it is in each frame, when it
    moves), coloured by time as in Fig. 4; the title names the law that ran."""
    m = res.model
    r = m.radius(m.s_nodes)
    idx = snapshot_indices(res, frames)
    _, pts = boundary.sample(400)
    fig = Figure(figsize=(4.4, 4), layout="constrained")
    FigureCanvasAgg(fig)  # an animation draws frames through a canvas
    ax = fig.subplots()
    # limits from every frame and the object in it, so no frame is clipped
    xs = np.concatenate([res.x[idx].reshape(-1, 2), *(res.object_at(k, pts) for k in idx)])
    pad = float(r.max()) + 0.005
    colours = dict(zip(idx.tolist(), snapshot_colours(len(idx)), strict=True))
    lo, hi = xs.min(axis=0) - pad, xs.max(axis=0) + pad

    def draw(k: int) -> None:
        ax.clear()
        obj = res.object_at(k, pts)
        ax.fill(obj[:, 0], obj[:, 1], color="0.75")
        _draw_arm(ax, res.x[k], r, color=colours[k], alpha=0.7, lw=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        plane_axes(ax)
        ax.set_title(f"{LAW_TITLES[res.law]}: simulated time t = {res.t[k]:.2f} s", fontsize=9)

    anim = FuncAnimation(fig, draw, frames=idx)
    try:
        anim.save(path, writer=PillowWriter(fps=12))
    except (OSError, ValueError) as exc:
        raise output_error(f"the animation {path}", exc) from exc
