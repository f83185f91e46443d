"""Figures of a graph run (Fig. 4 style, and the grasp quality over time), drawn from what travelled over the topics.

Top: six snapshots of the arm (with its radius) around the object. Bottom: rho/rho_d and
alpha along s at those times, with the static theoretical solution of eq. (20)
(closed-loop kinematics from the base's contact state, :func:`contgrasp_core.control.closed_loop_kinematics`)
dashed: the equilibrium of the law without the object (it ignores contact, so it may cut into
the object). Every time is the header stamp of the messages drawn (simulated time).
"""

from __future__ import annotations

import textwrap
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from contgrasp_core.arm import ArmShape
from contgrasp_core.errors import ContgraspError
from contgrasp_core.control.law import adaptive_mu2, closed_loop_kinematics
from contgrasp_core.figures.closed_loop import LAW_TITLES, STATIC_LABEL, finish_profile_panels, plane_axes, snapshot_colours
from contgrasp_core.figures.draw import draw_arm, draw_boundary, save
from contgrasp_core.rod.body import to_world
from contgrasp_core.scenario import Scenario

__all__ = ["TIME_LABEL", "QUALITY_AXES", "CREEP_NOTE", "build_run_figure", "run_figure", "quality_history_figure"]


TIME_LABEL = "simulated time t [s] (message header stamp)"
"""What a run figure's times are: the header stamp of the messages drawn (a rod state and the
contact state of the same step carry the same stamp), i.e. simulated time, both in the live figure
(``contgrasp-launch --plot``) and in the one drawn from a bag (``contgrasp analyze --plot``)."""


def build_run_figure(summary: dict[str, Any], params: dict[str, dict[str, Any]]) -> Figure:
    """The figure of ``summary['history']`` (snapshots of rod state + contact state of one step,
    each labelled by its header stamp): the arm around the object at six times (legend), and
    rho/rho_d (log scale, limits from the data) and alpha along s at those times, with the
    targets and, for a circle under the paper's law, the static solution of eq. (20). A movable
    object is drawn at its start pose (filled) and, dashed, where it is at the last snapshot.
    The title names the law that ran."""
    hist = summary["history"]
    ctl = params["grasp_controller"]
    scenario = Scenario.from_ros_parameters(params)
    boundary = scenario.object.boundary()
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
    colours = snapshot_colours(len(picks))
    for colour, i in zip(colours, picks, strict=True):
        h = hist[i]
        shape = ArmShape(np.asarray(h["s"]), np.stack([h["x"], h["y"]], -1), np.asarray(h["theta"]))
        draw_arm(ax, shape, np.asarray(h["radius"]), color=colour, alpha=0.45, label=f"t = {h['t']:.2f} s")
    last = hist[picks[-1]]
    if len(last.get("object_q") or ()):  # a movable object: where it is at the last snapshot
        _, pts = boundary.sample(720)
        moved = to_world(np.vstack([pts, pts[:1]]), np.asarray(last["object_q"]), np.asarray(last["object_centroid"]))
        ax.plot(moved[:, 0], moved[:, 1], "k--", lw=1.0, zorder=2, label=f"object at t = {last['t']:.2f} s")
    plane_axes(ax)
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, title=TIME_LABEL.replace(" (", "\n("),
              title_fontsize=8)
    ax.set_title(f"closed-loop grasp through the ROS graph ({LAW_TITLES[scenario.law]})")
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
    if boundary.kind == "circle" and scenario.law == "paper" and ctl.get("adaptive_mu2", True):
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


QUALITY_AXES = (
    ("Q1 = $\\lambda_{min}(W)$ [cm$^3$]", 1e6),
    ("Q2 = det W [cm$^5$]", 1e10),
    ("Q3 = $\\lambda_{min} / \\lambda_{max}$ [-]", 1.0),
)
"""Label and scale from SI of each metric's axis. W = int_S G G^T ds with rows (f_x, f_y, torque)
(:mod:`contgrasp_core.quality`): its force block is in m, its torque block in m^3, so det W is
in m^5 and lambda_min, for an object much smaller than 1 m, is the torque direction's, m^3;
cm^3 and cm^5 give plain numbers (no 1e-5 / 1e-7 axis multipliers) for the paper's 2.5 cm circle."""

CREEP_NOTE = ("'settled' means every node slower than the settle speed, not at rest: the arm still moves by fractions "
              "of a mm, which moves the ends of the contact set and so W; Q2 = det W (a product of three eigenvalues) "
              "changes most")
"""Why Q1..Q3 still move after the settled line of :func:`quality_history_figure`."""


def quality_history_figure(t: np.ndarray, q: tuple[np.ndarray, np.ndarray, np.ndarray], path: str, *,
                           recomputed_t: np.ndarray | None = None, recomputed: np.ndarray | None = None,
                           settle_time: float | None = None, settle_rule: tuple[float, float] | None = None) -> Figure:
    """Q1, Q2, Q3 (paper Sec. IV) over sim time ``t`` as recorded (lines), optionally recomputed
    from the rod states (crosses, ``recomputed`` (K, 3) at ``recomputed_t``), to ``path``; returns
    the figure. Axes in the units of :data:`QUALITY_AXES` without offsets; ``settle_time`` is
    drawn as a line whose legend entry states the settle rule (``settle_rule`` = (settle_speed
    [m/s], settle_hold [s]) of the simulator) and :data:`CREEP_NOTE` says why the metrics still move."""
    fig = Figure(figsize=(8, 8.4), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for n, (ax, rec_vals, (label, scale)) in enumerate(zip(axes, q, QUALITY_AXES, strict=True)):
        ax.plot(t, np.asarray(rec_vals) * scale, "-", color="tab:blue", lw=1.2, label="recorded")
        if recomputed is not None and recomputed_t is not None and len(recomputed_t):
            ax.plot(recomputed_t, recomputed[:, n] * scale, "x", color="tab:red", ms=5, label="recomputed")
        if settle_time is not None:
            rule = ("every node slower than settle_speed for settle_hold" if settle_rule is None else
                    f"every node slower than {settle_rule[0] * 1e3:g} mm/s for {settle_rule[1]:g} s")
            ax.axvline(settle_time, color="0.5", ls=":", lw=1.0, label=f"settled: {rule}")
        ax.set_ylabel(label)
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title("continuum grasp quality (Sec. IV) over the run")
    axes[-1].set_xlabel(TIME_LABEL)
    if settle_time is not None:
        fig.text(0.5, 0.0, textwrap.fill(CREEP_NOTE, 110), ha="center", va="bottom", fontsize=8, color="0.3")
        fig.get_layout_engine().set(rect=(0.0, 0.05, 1.0, 0.95))  # type: ignore[union-attr, call-arg]
    save(fig, path)
    return fig
