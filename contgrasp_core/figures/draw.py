"""Matplotlib drawing helpers shared by the figures.

Figures are built with matplotlib's object API (:class:`~matplotlib.figure.Figure`, no pyplot),
so importing or using this package never selects or switches a backend: a notebook keeps its own.
"""

from __future__ import annotations

import re
import textwrap

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from ..arm import ArmShape
from ..boundary import Boundary
from ..contact import ContactKinematics, ContactState
from ..errors import InvalidParameterError, output_error
from ..outputs import check_output

__all__ = ["draw_boundary", "draw_arm", "kinematics_figure", "save", "check_figure_path", "wrap_title"]


def check_figure_path(path: object, option: str = "--plot") -> None:
    """Raise InvalidParameterError unless ``path`` names a file matplotlib can write (a known
    suffix, or none for PNG) where this process can write it (:func:`~contgrasp_core.outputs.check_output`;
    called before any computation, so a typo does not waste a run)."""
    from pathlib import Path

    from matplotlib.backend_bases import FigureCanvasBase

    if not isinstance(path, str | Path) or not str(path):
        raise InvalidParameterError(f"{option} must be a file name, got {path!r}")
    p = Path(path)
    fmt = p.suffix[1:].lower()
    supported = FigureCanvasBase.get_supported_filetypes()
    if fmt and fmt not in supported:
        raise InvalidParameterError(f"{option} {path}: unknown figure format {fmt!r}; use one of {', '.join(sorted(supported))}")
    check_output(p, option)


_KEEP_WITH_NUMBER = re.compile(r" (?=[-+(]?\d)")


def wrap_title(title: str, width: int) -> str:
    """``title`` wrapped at spaces to lines of at most ``width`` characters, its own line breaks
    kept; a number stays on the line of the word before it ("max discrepancy 3.9e-09", "eq. (8)"
    are never split), and hyphens are no break points."""
    nbsp = "\u00a0"  # textwrap breaks at ASCII whitespace only
    lines = (textwrap.fill(_KEEP_WITH_NUMBER.sub(nbsp, line), width, break_on_hyphens=False) for line in title.split("\n"))
    return "\n".join(lines).replace(nbsp, " ")


def draw_boundary(ax: Axes, boundary: Boundary, **kw: object) -> None:
    """Object outline, filled light grey."""
    _, pts = boundary.sample(720)
    pts = np.vstack([pts, pts[:1]])
    ax.fill(pts[:, 0], pts[:, 1], color=kw.pop("color", "0.85"), zorder=1)
    ax.plot(pts[:, 0], pts[:, 1], color="k", lw=1.0, zorder=2)


def arm_outline(shape: ArmShape, radius: ArrayLike) -> NDArray[np.float64]:
    """Closed polygon of the arm's body: centreline offset by +-radius along b = R(pi/2) a."""
    rad = np.broadcast_to(np.asarray(radius, dtype=float), shape.s.shape)
    b = np.stack([-np.sin(shape.theta), np.cos(shape.theta)], axis=-1)
    left = shape.r + rad[:, None] * b
    right = shape.r - rad[:, None] * b
    return np.vstack([left, right[::-1], left[:1]])


def draw_arm(ax: Axes, shape: ArmShape, radius: ArrayLike, *, color: str = "tab:purple", alpha: float = 0.6, label: str | None = None) -> None:
    """Arm drawn with its (possibly tapered) radius, centreline dashed, base marked."""
    poly = arm_outline(shape, radius)
    ax.fill(poly[:, 0], poly[:, 1], color=color, alpha=alpha, lw=0, zorder=3, label=label)
    ax.plot(shape.r[:, 0], shape.r[:, 1], color="k", lw=0.6, ls="--", zorder=4)
    ax.plot(shape.r[0, 0], shape.r[0, 1], "ks", ms=4, zorder=5)


def kinematics_figure(
    boundary: Boundary,
    shape: ArmShape,
    radius: ArrayLike,
    ode: ContactKinematics,
    geo: ContactState,
    *,
    title: str = "",
    unit: str = "-",
) -> Figure:
    """Arm around the object with its shadow points; rho and alpha against s/L (ODE vs geometry).
    ``unit`` names the length unit of the axes (``-``: the paper's dimensionless Fig. 2 units);
    the title is wrapped to the figure's width by :func:`wrap_title` (constrained layout keeps it
    inside); the legend is under the arm's axes, off the object."""
    fig = Figure(figsize=(10, 5.0), layout="constrained")
    grid = fig.add_gridspec(1, 2, width_ratios=(1.1, 1.0))
    left, right = fig.add_subfigure(grid[0]), fig.add_subfigure(grid[1])
    ax = left.add_subplot(1, 1, 1)
    draw_boundary(ax, boundary)
    ax.fill([], [], color="0.85", label="object")
    draw_arm(ax, shape, radius, label="arm (with its radius)")
    step = max(1, len(shape.s) // 40)
    for i in range(0, len(shape.s), step):
        ax.plot([shape.r[i, 0], geo.foot[i, 0]], [shape.r[i, 1], geo.foot[i, 1]], color="tab:orange", lw=0.5, zorder=4)
    ax.plot(geo.foot[::step, 0], geo.foot[::step, 1], "o", color="tab:orange", ms=2.5, zorder=5, label="shadow points")
    ax.set_aspect("equal")
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    left.legend(loc="outside lower center", ncols=3, fontsize=8)  # below the axes: never over the object
    fig.suptitle(wrap_title(title or "arm and shadow curve", 90), fontsize=10)
    sl = shape.s / shape.s[-1]
    ax1, ax2 = right.subplots(2, 1, sharex=True)
    ax1.plot(sl, ode.rho, "C0", label="rho (ODE, eq. (8))")
    ax1.plot(sl, geo.rho, "k:", label="rho (geometry, eq. (4))")
    ax1.set_ylabel(f"rho [{unit}]")
    ax1.set_xlabel("s / L [-]")
    ax1.legend(fontsize=8)
    ax2.plot(sl, ode.alpha, "C1", label="alpha (ODE, eq. (8))")
    ax2.plot(sl, geo.alpha, "k:", label="alpha (geometry, eq. (4))")
    ax2.axhline(np.pi / 2, color="0.5", ls="--", lw=0.8, label="pi / 2")
    ax2.set_ylabel("alpha [rad]")
    ax2.set_xlabel("s / L [-]")
    ax2.legend(fontsize=8)
    return fig


def save(fig: Figure, path: str, dpi: int = 130) -> None:
    """Write the figure (format from the file suffix)."""
    from pathlib import Path

    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi)
    except (OSError, ValueError) as exc:
        raise output_error(f"the figure {path}", exc) from exc
