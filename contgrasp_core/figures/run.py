"""Figures of a graph run (Fig. 4 style, and the grasp quality over time), drawn from what travelled over the topics.

Top: six snapshots of the arm (with its radius) around the object. Bottom: rho/rho_d and
alpha along s at those times, with the static theoretical solution of eq. (20)
(closed-loop kinematics from the base's contact state, :func:`contgrasp_core.control.closed_loop_kinematics`)
dashed: the equilibrium of the law without the object (it ignores contact, so it may cut into
the object). Every time is the header stamp of the messages drawn (simulated time).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from contgrasp_core.arm import ArmShape
from contgrasp_core.errors import ContgraspError
from contgrasp_core.control.law import adaptive_mu2, closed_loop_kinematics
from contgrasp_core.figures.closed_loop import STATIC_LABEL, finish_profile_panels
from contgrasp_core.figures.draw import draw_arm, draw_boundary, save
from contgrasp_core.rod.body import to_world
from contgrasp_core.scenario import Scenario

__all__ = ["TIME_LABEL", "build_run_figure", "run_figure", "quality_history_figure"]


TIME_LABEL = "simulated time t [s] (message header stamp)"
"""What a run figure's times are: the header stamp of the messages drawn (a rod state and the
contact state of the same step carry the same stamp), i.e. simulated time, both in the live figure
(``contgrasp-launch --plot``) and in the one drawn from a bag (``contgrasp analyze --plot``)."""


def build_run_figure(summary: dict[str, Any], params: dict[str, dict[str, Any]]) -> Figure:
    """The figure of ``summary['history']`` (snapshots of rod state + contact state of one step,
    each labelled by its header stamp): the arm around the object at six times (legend), and
    rho/rho_d (log scale, limits from the data) and alpha along s at those times, with the
    targets and, for a circle, the static solution of eq. (20). A movable object is drawn at
    its start pose (filled) and, dashed, where it is at the last snapshot."""
    hist = summary["history"]
    ctl = params["grasp_controller"]
    boundary = Scenario.from_ros_parameters(params).object.boundary()
    # the motion happens early (the arm swings in within ~0.3 s): snapshots at the start, through
    # the swing, and at the end
    times = np.array([h["t"] for h in hist])
    wanted = [0.0, 0.05, 0.1, 0.15, 0.25, times[-1]]
    picks = np.unique([int(np.argmin(np.abs(times - w))) for w in wanted])
    fig = Figure(figsize=(11, 9), layout="constrained")
    grid = fig.add_gridspec(2, 1, height_ratios=(1.0, 0.9))
    top, bottom = fig.add_subfigure(grid[0]), fig.add_subfigure(grid[1])
    ax = top.add_subplot(1, 1, 1)
    draw_boundary(ax, boundary)
    colours = colormaps["Purples"](np.linspace(0.35, 1.0, len(picks)))
    for colour, i in zip(colours, picks, strict=True):
        h = hist[i]
        shape = ArmShape(np.asarray(h["s"]), np.stack([h["x"], h["y"]], -1), np.asarray(h["theta"]))
        draw_arm(ax, shape, np.asarray(h["radius"]), color=colour, alpha=0.45, label=f"t = {h['t']:.2f} s")
    last = hist[picks[-1]]
    if len(last.get("object_q") or ()):  # a movable object: where it is at the last snapshot
        _, pts = boundary.sample(720)
        moved = to_world(np.vstack([pts, pts[:1]]), np.asarray(last["object_q"]), np.asarray(last["object_centroid"]))
        ax.plot(moved[:, 0], moved[:, 1], "k--", lw=1.0, zorder=2, label=f"object at t = {last['t']:.2f} s")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, title=TIME_LABEL.replace(" (", "\n("),
              title_fontsize=8)
    ax.set_title("closed-loop grasp through the ROS graph (feedback law eq. (19))")
    ax_r, ax_a = bottom.subplots(1, 2)
    ratios, alphas = [], []
    for colour, i in zip(colours, picks, strict=True):
        h = hist[i]
        s, radius = np.asarray(h["s"]), np.asarray(h["radius"])
        ratios.append(np.asarray(h["rho"]) / radius)
        alphas.append(np.asarray(h["alpha"]))
        ax_r.plot(s / s[-1], ratios[-1], color=colour, lw=1.2, label=f"t = {h['t']:.2f} s")
        ax_a.plot(s / s[-1], alphas[-1], color=colour, lw=1.2, label=f"t = {h['t']:.2f} s")
    h = hist[-1]
    s, radius = np.asarray(h["s"]), np.asarray(h["radius"])
    if boundary.kind == "circle" and ctl.get("adaptive_mu2", True):
        lu = ctl["length_unit"]
        mu2 = adaptive_mu2(radius, ctl["object_radius"], length_unit=lu)
        try:
            static = closed_loop_kinematics(
                h["rho"][0], h["alpha"][0], s, ctl["mu1"], lambda sv: np.interp(sv, s, mu2),
                1.0 / boundary.params["R"], length_unit=lu,
            )
        except ContgraspError:
            pass  # no admissible static solution from this base state: nothing to draw
        else:
            ratios.append(static.rho / radius)
            alphas.append(static.alpha)
            ax_r.plot(s / s[-1], ratios[-1], "k--", lw=1.0, label=STATIC_LABEL)
            ax_a.plot(s / s[-1], alphas[-1], "k--", lw=1.0, label=STATIC_LABEL)
    finish_profile_panels(ax_r, ax_a, ratios, alphas, bottom, ncols=4, fontsize=8)
    return fig


def run_figure(summary: dict[str, Any], params: dict[str, dict[str, Any]], path: str) -> None:
    """Draw :func:`build_run_figure` of ``summary['history']`` (the launcher's monitor samples, or
    the same picked from a bag) to ``path``."""
    save(build_run_figure(summary, params), path)


def quality_history_figure(t: np.ndarray, q: tuple[np.ndarray, np.ndarray, np.ndarray], path: str, *,
                           recomputed_t: np.ndarray | None = None, recomputed: np.ndarray | None = None,
                           settle_time: float | None = None) -> None:
    """Q1, Q2, Q3 (paper Sec. IV) over sim time ``t`` as recorded (lines), optionally recomputed
    from the rod states (crosses, ``recomputed`` (K, 3) at ``recomputed_t``), to ``path``."""
    fig = Figure(figsize=(8, 8))
    axes = fig.subplots(3, 1, sharex=True)
    labels = ("Q1 = lambda_min(W)", "Q2 = det W", "Q3 = lambda_min / lambda_max")
    for n, (ax, rec_vals, label) in enumerate(zip(axes, q, labels, strict=True)):
        ax.plot(t, rec_vals, "-", color="tab:blue", lw=1.2, label="recorded")
        if recomputed is not None and recomputed_t is not None and len(recomputed_t):
            ax.plot(recomputed_t, recomputed[:, n], "x", color="tab:red", ms=5, label="recomputed")
        if settle_time is not None:
            ax.axvline(settle_time, color="0.5", ls=":", lw=1.0, label="settled")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title("continuum grasp quality (Sec. IV) over the run")
    axes[-1].set_xlabel(TIME_LABEL)
    fig.tight_layout()
    save(fig, path)
