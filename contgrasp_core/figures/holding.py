"""The holding study's figure: the static quality map beside the measured stiffness and capacity."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..quality_map import QualityMap
from .draw import draw_boundary, save

__all__ = ["study_figure", "plot_study"]

_PANELS = (("static_Q1", "static Q1\n(the paper's optimal grasp)", "Q1 [-]"),
           ("stiffness_min", "measured lambda_min of K's\nscaled symmetric part", "N/m"),
           ("capacity_min", "measured worst-direction\nholding capacity", "N"))


_FAILED = {"no contact": ("x", "tab:red"), "not settled": ("+", "tab:orange"), "not held": ("d", "tab:purple")}
"""How a pose without a measured grasp is drawn, by its outcome (:mod:`contgrasp_core.holding_study`)."""


def study_figure(qm: QualityMap, rows: list[dict[str, Any]]) -> Figure:
    """Three panels over the base poses (paper units, about the object): the static map's Q1,
    the grasp's measured lambda_min of K's scaled symmetric part and its worst-direction
    capacity (circles; other markers: no measured grasp there, by outcome), and a fourth with each quality measure
    ranked against the capacity."""
    fig = Figure(figsize=(18, 4.8))
    grid = {r["key"]: r for r in rows if r["key"].startswith("grid:")}
    pos: dict[str, list[np.ndarray]] = {k: [] for k, _, _ in _PANELS}
    vals: dict[str, list[float]] = {k: [] for k, _, _ in _PANELS}
    failed: dict[str, list[np.ndarray]] = {}
    for key, r in grid.items():
        i, j = (int(v) for v in key[5:].split(","))
        xy = qm.base[i, j, :2]
        for name, _, _ in _PANELS:
            value = r.get(name)
            if r.get("status") == "ok" and value is not None and np.isfinite(value):
                pos[name].append(xy)
                vals[name].append(value)
        if r.get("status") != "ok":
            failed.setdefault(r.get("outcome", "no settled grasp"), []).append(xy)
    for k, (name, title, unit) in enumerate(_PANELS):
        ax = fig.add_subplot(1, 4, k + 1)
        draw_boundary(ax, qm.spec.boundary(), color="0.85")
        if vals[name]:
            p = np.array(pos[name])
            sc = ax.scatter(p[:, 0], p[:, 1], c=vals[name], cmap="viridis", s=60, edgecolors="k", linewidths=0.4, zorder=3)
            fig.colorbar(sc, ax=ax, shrink=0.75, label=unit, format="%.3g")
        for outcome, where in sorted(failed.items()):
            f = np.array(where)
            style = _FAILED.get(outcome, ("*", "tab:gray"))
            ax.plot(f[:, 0], f[:, 1], style[0], color=style[1], ms=6, label=outcome, zorder=3)
        if failed:
            ax.legend(loc="lower right", fontsize=7)
        ax.set_aspect("equal")
        ax.set_xlabel("base x [paper units]")
        ax.set_ylabel("base y [paper units]")
        ax.set_title(title, fontsize=10)
    ax = fig.add_subplot(1, 4, 4)
    ok = [r for r in grid.values() if r.get("status") == "ok"]
    if ok:
        cap = np.array([r["capacity_min"] for r in ok])
        for name, marker in (("static_Q1", "o"), ("Q1", "s"), ("Q3", "^")):
            q = np.array([r.get(name, np.nan) for r in ok], dtype=float)
            good = np.isfinite(q)
            if good.sum() >= 2:
                ax.plot(_ranks(q[good]), _ranks(cap[good]), marker, ls="none", alpha=0.7, label=name)
        ax.legend(loc="upper left", fontsize=8)
    ax.set_xlabel("rank of the quality measure")
    ax.set_ylabel("rank of the worst capacity")
    ax.set_title("ranks: quality against capacity", fontsize=10)
    fig.suptitle(f"holding study, {qm.spec.object.text()}: {len(ok)} of {len(grid)} poses grasped", fontsize=11)
    fig.tight_layout()
    return fig


def _ranks(v: np.ndarray) -> np.ndarray:
    from scipy.stats import rankdata

    return np.asarray(rankdata(v), dtype=float)


def plot_study(qm: QualityMap, rows: list[dict[str, Any]], path: str | Path) -> Path:
    """Draw :func:`study_figure` to ``path``."""
    save(study_figure(qm, rows), str(path))
    return Path(path)
