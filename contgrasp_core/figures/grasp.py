"""Figure 2 of the paper: optimal grasping configurations (matplotlib object API).

One panel per object: (top) the arm drawn with its tapered radius around the object;
(middle) rho/rho_d and alpha against s/L with their targets 1 and alpha_d dashed;
(bottom) the arm curvature kappa and the object curvature kappa_o(s_o(s)) (dashed) against s/L.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from ..errors import InvalidParameterError
from ..optimal import GraspResult
from .draw import save

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["plot_grasp", "save_grasp_figure"]

_ARM = "#7b4fa0"
_BLUE = "#1f77b4"
_ORANGE = "#ff7f0e"


def plot_grasp(result: GraspResult, axes: Sequence[Axes] | None = None, title: str | None = None) -> Figure:
    """Draw one Fig. 2 column for ``result`` into three axes (created if None); returns the figure."""
    if axes is None:
        fig = Figure(figsize=(4.2, 7.2))
        axes = fig.subplots(3, 1, gridspec_kw={"height_ratios": [1.7, 1, 1]})
    else:
        parent = axes[0].figure
        if not isinstance(parent, Figure):  # (tight_layout below needs the top-level figure)
            raise InvalidParameterError("plot_grasp: the axes must belong to a top-level figure, not a subfigure")
        fig = parent
    ax_arm, ax_ra, ax_k = axes
    p = result.problem
    s = result.s
    t = s / s[-1]
    # --- object and arm
    _, pts = p.boundary.sample(720)
    ax_arm.fill(pts[:, 0], pts[:, 1], color="0.82", ec="0.35", lw=1.0, zorder=1)
    r = result.shape.r
    th = result.shape.theta
    rad = p.arm.radius(s)
    nrm = np.stack([-np.sin(th), np.cos(th)], axis=-1)
    left = r + rad[:, None] * nrm
    right = r - rad[:, None] * nrm
    outline = np.vstack([left, right[::-1]])
    ax_arm.fill(outline[:, 0], outline[:, 1], color=_ARM, alpha=0.75, lw=0.0, zorder=2)
    ax_arm.plot(r[:, 0], r[:, 1], color="k", lw=0.5, zorder=3)
    ax_arm.add_patch(Circle(r[0], rad[0], color=_ARM, alpha=0.75, lw=0, zorder=2))
    ax_arm.plot(*r[0], "ko", ms=3, zorder=4)
    ax_arm.set_aspect("equal")
    ax_arm.axis("off")
    if title:
        ax_arm.set_title(title)
    # --- rho / rho_d and alpha
    ax_ra.plot(t, result.rho / p.disc.rho_d, color=_BLUE, lw=1.5, label=r"$\rho/\rho_d$")
    ax_ra.plot(t, result.alpha, color=_ORANGE, lw=1.5, label=r"$\alpha$")
    ax_ra.plot(t, np.ones_like(t), "--", color=_BLUE, lw=1.0)
    ax_ra.plot(t, p.disc.alpha_d, "--", color=_ORANGE, lw=1.0)
    ax_ra.set_xlim(0, 1)
    top = max(float(np.max(result.rho / p.disc.rho_d)), float(np.max(result.alpha)), 2.0)
    ax_ra.set_ylim(0.0, 1.08 * top)
    ax_ra.legend(loc="upper right", fontsize=8, frameon=False)
    ax_ra.set_xlabel("$s/L$")
    # --- curvatures
    ax_k.plot(t, result.kappa, color=_BLUE, lw=1.5, label=r"$\kappa$")
    ax_k.plot(t, result.kappa_o, "--", color="k", lw=1.0, label=r"$\kappa_o$")
    ax_k.set_xlim(0, 1)
    lo = min(float(np.min(result.kappa_o)), float(np.percentile(result.kappa, 2))) - 0.1
    hi = max(float(np.max(result.kappa_o)), float(np.percentile(result.kappa, 98))) + 0.1
    ax_k.set_ylim(lo, hi)
    ax_k.legend(loc="upper right", fontsize=8, frameon=False)
    ax_k.set_xlabel("$s/L$")
    fig.tight_layout()
    return fig


def save_grasp_figure(result: GraspResult, path: str | Path, title: str | None = None) -> Path:
    """Render :func:`plot_grasp` to ``path`` (PNG/PDF/SVG by extension)."""
    save(plot_grasp(result, title=title), str(path))
    return Path(path)
