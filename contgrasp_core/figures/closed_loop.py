"""Fig. 4 of the paper: the closed-loop grasp on the rod engine (snapshots, rho/rho_d and alpha
along the arm against the static solution) and its animation."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..boundary import Boundary
from ..control import static_solution
from ..errors import output_error
from ..rod.closed_loop import ClosedLoopResult
from .draw import save

__all__ = ["snapshot_indices", "plot_fig4", "animate"]


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
    alpha along s at several times, the static solution of eq. (20) dashed."""
    m = res.model
    r = m.radius(m.s_nodes)
    fig = Figure(figsize=(7.0, 7.5))
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
    ax0.set_title("closed-loop grasp (eq. (19)), six time instances")
    ax1 = fig.add_subplot(2, 2, 3)
    ax2 = fig.add_subplot(2, 2, 4)
    s_n = m.s_nodes / m.length
    cmap = colormaps["Blues"]
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
    save(fig, path, dpi=150)


def animate(res: ClosedLoopResult, boundary: Boundary, path: str, frames: int = 60) -> None:
    """GIF of the arm (with its radius) wrapping the object."""
    m = res.model
    r = m.radius(m.s_nodes)
    idx = snapshot_indices(res, frames)
    _, pts = boundary.sample(400)
    fig = Figure(figsize=(4, 4))
    FigureCanvasAgg(fig)  # an animation draws frames through a canvas
    ax = fig.subplots()

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
        raise output_error(f"the animation {path}", exc) from exc
