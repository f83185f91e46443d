"""The holding study's figure: the static quality map beside the measured stiffness and capacity."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import SymLogNorm
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ..quality_map import QualityMap
from .draw import draw_boundary, save

__all__ = ["study_figure", "plot_study"]

_PANELS = (("stiffness_min", "measured lambda_min of K's\nscaled symmetric part", "N/m"),
           ("capacity_min", "measured worst-direction\nholding capacity", "N"))

_FAILED = {"no contact": ("x", "tab:red"), "not settled": ("+", "tab:orange"), "not held": ("d", "tab:purple")}
"""How a pose without a measured grasp is drawn, by its outcome (:mod:`contgrasp_core.holding.study`)."""


def study_figure(qm: QualityMap, rows: list[dict[str, Any]]) -> Figure:
    """Four panels: over the base poses (paper units, about the object) the static map's Q1 at
    every pose (ringed: the grasp held there), the measured lambda_min of K's scaled symmetric
    part (symmetric log colour scale: it spans decades and both signs) and the worst-direction
    capacity (circles; other markers: no measured grasp there, by outcome); and the distinct
    poses' quality measures ranked against their capacity (symmetric copies left out)."""
    fig = Figure(figsize=(18, 4.8))
    grid = {r["key"]: r for r in rows if r["key"].startswith("grid:")}
    held = {k: r for k, r in grid.items() if r.get("status") == "ok"}
    failed: dict[str, list[np.ndarray]] = {}
    for key, r in grid.items():
        if r.get("status") != "ok":
            failed.setdefault(r.get("outcome", "no settled grasp"), []).append(_where(qm, key))
    ax = _map_axes(fig, 1, qm)
    valid = qm.valid & np.isfinite(qm.Q[0])
    sc = ax.scatter(qm.base[..., 0][valid], qm.base[..., 1][valid], c=qm.Q[0][valid], cmap="viridis", s=45, zorder=3)
    fig.colorbar(sc, ax=ax, shrink=0.75, label="Q1 [-]", format="%.3g")
    if held:
        p = np.array([_where(qm, k) for k in held])
        ax.scatter(p[:, 0], p[:, 1], s=110, facecolors="none", edgecolors="k", linewidths=1.2, zorder=4, label="held")
        ax.legend(loc="lower right", fontsize=7)
    ax.set_title("static Q1 (the paper's optimal grasp)\nat every pose", fontsize=10)
    for k, (name, title, unit) in enumerate(_PANELS):
        ax = _map_axes(fig, k + 2, qm)
        measured = [(_where(qm, key), float(r[name])) for key, r in held.items() if np.isfinite(r.get(name, np.nan))]
        if measured:
            p = np.array([m[0] for m in measured])
            v = np.array([m[1] for m in measured])
            norm, ticks = _symlog(v) if name == "stiffness_min" else (None, None)
            sc = ax.scatter(p[:, 0], p[:, 1], c=v, cmap="viridis", norm=norm, s=60, edgecolors="k", linewidths=0.4, zorder=3)
            fig.colorbar(sc, ax=ax, shrink=0.75, label=unit, format="%.3g", ticks=ticks)
        for outcome, where in sorted(failed.items()):
            f = np.array(where)
            style = _FAILED.get(outcome, ("*", "tab:gray"))
            ax.plot(f[:, 0], f[:, 1], style[0], color=style[1], ms=6, label=outcome, zorder=3)
        if failed:
            ax.legend(loc="lower right", fontsize=7)
        ax.set_title(title, fontsize=10)
    ax = fig.add_subplot(1, 4, 4)
    distinct = [r for r in held.values() if "same_as" not in r]
    if distinct:
        cap = np.array([r["capacity_min"] for r in distinct])
        for name, marker in (("static_Q1", "o"), ("static_QH", "D"), ("cage_QH", "^"), ("Q1", "s")):
            q = np.array([r.get(name, np.nan) for r in distinct], dtype=float)
            good = np.isfinite(q)
            if good.sum() >= 2:
                ax.plot(_ranks(q[good]), _ranks(cap[good]), marker, ls="none", alpha=0.7, label=name)
        ax.legend(loc="upper left", fontsize=8)
    ax.set_xlabel("rank of the quality measure")
    ax.set_ylabel("rank of the worst capacity")
    for axis in (ax.xaxis, ax.yaxis):  # (ranks are whole numbers; ties share their mean rank)
        axis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title("distinct poses: quality against capacity", fontsize=10)
    fig.suptitle(f"holding study, {qm.spec.object.text()}: held at {len(held)} of {len(grid)} grid poses "
                 f"({len(distinct)} distinct up to the object's symmetry)", fontsize=11)
    fig.tight_layout()
    return fig


def _symlog(values: np.ndarray) -> tuple[SymLogNorm, list[float]]:
    """A symmetric log colour scale for ``values`` spanning decades and both signs (linear within
    three decades of the largest magnitude, about 0) and its colour bar's ticks: 0 and plus and
    minus each power of ten from two decades below the largest up (a tick at the linear part's
    edge would print over 0's)."""
    span = max(float(np.abs(values).max()), 1e-12)
    top = int(np.floor(np.log10(span)))
    ticks = [0.0] + [sign * 10.0**k for k in range(top - 2, top + 1) for sign in (-1.0, 1.0)]
    return SymLogNorm(linthresh=10.0 ** (top - 3), vmin=-span, vmax=span), sorted(ticks)


def _where(qm: QualityMap, key: str) -> np.ndarray:
    """The base position (paper units) of the grid pose ``grid:i,j``."""
    i, j = (int(v) for v in key[5:].split(","))
    return np.asarray(qm.base[i, j, :2])


def _map_axes(fig: Figure, n: int, qm: QualityMap) -> Axes:
    ax = fig.add_subplot(1, 4, n)
    draw_boundary(ax, qm.spec.boundary(), color="0.85")
    ax.set_aspect("equal")
    ax.set_xlabel("base x [paper units]")
    ax.set_ylabel("base y [paper units]")
    return ax


def _ranks(v: np.ndarray) -> np.ndarray:
    from scipy.stats import rankdata

    return np.asarray(rankdata(v), dtype=float)


def plot_study(qm: QualityMap, rows: list[dict[str, Any]], path: str | Path) -> Path:
    """Draw :func:`study_figure` to ``path``."""
    save(study_figure(qm, rows), str(path))
    return Path(path)
