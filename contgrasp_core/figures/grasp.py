"""Figure 2 of the paper: optimal grasping configurations (matplotlib object API).

One panel per object: (top) the arm drawn with its tapered radius around the object;
(middle) rho/rho_d and alpha against s/L with their targets 1 and alpha_d dashed;
(bottom) the arm curvature kappa and the object curvature kappa_o(s_o(s)) (dashed) against s/L,
on a symmetric-log axis so the curvature peak near the base is shown, not clipped. Lengths are
the paper's dimensionless Fig. 2 units.
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
    ax_arm.fill(pts[:, 0], pts[:, 1], color="0.82", ec="0.35", lw=1.0, zorder=1, label="object")
    r = result.shape.r
    th = result.shape.theta
    rad = p.arm.radius(s)
    nrm = np.stack([-np.sin(th), np.cos(th)], axis=-1)
    left = r + rad[:, None] * nrm
    right = r - rad[:, None] * nrm
    outline = np.vstack([left, right[::-1]])
    ax_arm.fill(outline[:, 0], outline[:, 1], color=_ARM, alpha=0.75, lw=0.0, zorder=2, label="optimal arm")
    ax_arm.plot(r[:, 0], r[:, 1], color="k", lw=0.5, zorder=3)
    ax_arm.add_patch(Circle(r[0], rad[0], color=_ARM, alpha=0.75, lw=0, zorder=2))
    ax_arm.plot(*r[0], "ko", ms=3, zorder=4, label="base")
    ax_arm.set_aspect("equal")
    ax_arm.set_xlabel("x [-]")
    ax_arm.set_ylabel("y [-]")
    ax_arm.legend(loc="lower right", fontsize=6, frameon=False)
    if title:
        ax_arm.set_title(title)
    # --- rho / rho_d and alpha
    ax_ra.plot(t, result.rho / p.disc.rho_d, color=_BLUE, lw=1.5, label=r"$\rho/\rho_d$")
    ax_ra.plot(t, result.alpha, color=_ORANGE, lw=1.5, label=r"$\alpha$")
    ax_ra.plot(t, np.ones_like(t), "--", color=_BLUE, lw=1.0, label=r"target $\rho = \rho_d$")
    ax_ra.plot(t, p.disc.alpha_d, "--", color=_ORANGE, lw=1.0, label=r"target $\alpha_d$")
    ax_ra.set_xlim(0, 1)
    top = max(float(np.max(result.rho / p.disc.rho_d)), float(np.max(result.alpha)), 2.0)
    bottom = min(0.0, float(np.min(result.rho / p.disc.rho_d)), float(np.min(result.alpha)))
    ax_ra.set_ylim(bottom, 1.08 * top)
    ax_ra.legend(loc="upper right", fontsize=7, frameon=False, ncols=2)
    ax_ra.set_xlabel("s / L [-]")
    ax_ra.set_ylabel(r"$\rho/\rho_d$ [-], $\alpha$ [rad]")
    # --- curvatures
    ax_k.plot(t, result.kappa, color=_BLUE, lw=1.5, label=r"arm $\kappa$")
    ax_k.plot(t, result.kappa_o, "--", color="k", lw=1.0, label=r"object $\kappa_o(s_o(s))$")
    ax_k.set_xlim(0, 1)
    # the optimal curvature peaks near the base (up to ~10x the object's): a symmetric-log axis,
    # linear over the object's curvature range, shows every value instead of clipping the peak
    lin = 10.0 ** np.ceil(np.log10(max(2.0 * float(np.max(np.abs(result.kappa_o))), 1e-3)))  # a decade: clean ticks
    both = np.concatenate([result.kappa, result.kappa_o])
    ax_k.set_yscale("symlog", linthresh=lin)
    ax_k.set_ylim(float(both.min()) - 0.1 * lin, float(both.max()) + 0.1 * lin)
    ax_k.legend(loc="upper right", fontsize=7, frameon=False)
    ax_k.set_xlabel("s / L [-]")
    ax_k.set_ylabel(r"$\kappa$, $\kappa_o$ [-] (symlog)")
    fig.tight_layout()
    return fig


def save_grasp_figure(result: GraspResult, path: str | Path, title: str | None = None) -> Path:
    """Render :func:`plot_grasp` to ``path`` (PNG/PDF/SVG by extension)."""
    save(plot_grasp(result, title=title), str(path))
    return Path(path)
