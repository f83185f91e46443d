"""Fig. 3 of the paper: normalised quality maps over the base region D with the optimal grasp."""

from __future__ import annotations

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

from .draw import draw_boundary
from ..quality_map import METRICS, TIE_RTOL, QualityMap

__all__ = ["quality_map_figure", "TIE_NOTE"]

TIE_NOTE = (f"optimum: Nelder-Mead from the best grid pose; ties (values within {TIE_RTOL:g} relative, e.g. every "
            "polar angle of a circle, or psi and psi + pi of an ellipse) go to the smallest polar angle psi, then the smallest d")
"""The tie rule of :func:`contgrasp_core.quality_map.maximise`, printed under every Fig. 3."""


def _ring_triangulation(qm: QualityMap) -> tuple[Triangulation | None, np.ndarray]:
    """The grid's poses as triangles between neighbouring rings (None with one distance: a
    single ring has no area), and which poses have no base point."""
    P, D = qm.valid.shape
    x, y = qm.base[..., 0].ravel(), qm.base[..., 1].ravel()
    idx = np.arange(P * D).reshape(P, D)
    tris = []
    for i in range(P):
        a, b = idx[i], idx[(i + 1) % P]
        for j in range(D - 1):
            tris.append([a[j], b[j], b[j + 1]])
            tris.append([a[j], b[j + 1], a[j + 1]])
    bad = ~np.isfinite(x) | ~np.isfinite(y)
    if not tris:
        return None, bad
    xs, ys = np.where(bad, 0.0, x), np.where(bad, 0.0, y)
    return Triangulation(xs, ys, np.array(tris)), bad


def quality_map_figure(qm: QualityMap, *, title: str | None = None) -> Figure:
    """One panel per metric: heatmap over D normalised by its maximum (darker = higher), the
    object, the optimal base point (purple) and its arm configuration (purple dashed); the tie
    rule of the optimum (:data:`TIE_NOTE`) is printed under the panels. A map of one distance
    shows its poses as coloured points (a single ring spans no area)."""
    fig = Figure(figsize=(13, 4.6))
    t, bad = _ring_triangulation(qm)
    for k, metric in enumerate(METRICS):
        ax = fig.add_subplot(1, 3, k + 1)
        vals = qm.Q[k].ravel()
        finite = np.isfinite(vals) & ~bad
        vmax = np.nanmax(vals[finite]) if finite.any() else 1.0
        norm = np.where(finite, vals / vmax, 0.0)
        pc: ScalarMappable
        if t is None:  # (one distance: the poses themselves, coloured alike)
            pc = ax.scatter(qm.base[..., 0].ravel()[~bad], qm.base[..., 1].ravel()[~bad], c=norm[~bad], cmap="Greys",
                            vmin=0.0, vmax=1.0, s=40, edgecolors="0.5", zorder=3)
        else:
            t.set_mask(np.any(~finite[t.triangles], axis=1))
            pc = ax.tripcolor(t, norm, shading="gouraud", cmap="Greys", vmin=0.0, vmax=1.0)
        draw_boundary(ax, qm.spec.boundary(), color="0.75")
        opt = qm.optimum.get(metric)
        if opt:
            ax.plot(opt["base"]["x"], opt["base"]["y"], "o", color="purple", ms=7, zorder=6, label=f"base maximising {metric}")
            if opt.get("x") is not None:
                ax.plot(opt["x"], opt["y"], "--", color="purple", lw=2, zorder=6, label="its optimal arm")
        inv = ~qm.valid
        if inv.any():
            ax.plot(qm.base[..., 0][inv], qm.base[..., 1][inv], "x", color="tab:red", ms=4, label="invalid pose")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="lower right", fontsize=7)
        ax.set_aspect("equal")
        ax.set_xlabel("base x [-]")
        ax.set_ylabel("base y [-]")
        ax.set_title(f"{metric} / max {metric}" + (f"  (max {vmax:.3g})" if finite.any() else ""))
        fig.colorbar(pc, ax=ax, shrink=0.7, label=f"{metric} / max {metric} [-]")
    fig.suptitle(title or f"grasp quality maps: {qm.spec.object.text()}")
    fig.text(0.5, 0.01, TIE_NOTE, ha="center", va="bottom", fontsize=8, color="0.3")
    fig.tight_layout(rect=(0.0, 0.04, 1.0, 1.0))
    return fig
