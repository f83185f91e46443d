"""The figure package draws with matplotlib's object API and never touches the backend."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.heavy
def test_importing_and_drawing_figures_keeps_the_users_backend(tmp_path) -> None:
    """A notebook's backend survives importing every figure module and saving a figure."""
    code = f"""
import matplotlib
matplotlib.use("svg")
import contgrasp_core.figures.closed_loop, contgrasp_core.figures.grasp, contgrasp_core.figures.quality_map
from contgrasp_core.figures.draw import draw_boundary, save
from contgrasp_core.boundary import circle
from matplotlib.figure import Figure
fig = Figure()
draw_boundary(fig.subplots(), circle(1.0))
save(fig, {str(tmp_path / 'c.png')!r})
print(matplotlib.get_backend())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "svg"
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --- what a reviewer checks on every figure: labelled axes with units, a legend, and
# every curve inside the axes (no clipped data)

import re  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

UNIT = re.compile(r"\[[^\]]+\]")  # "x [cm]", "s / L [-]", "alpha [rad]"
SAMPLE_BAG = Path(__file__).resolve().parents[1] / "bags" / "paper_grasp.mcap"


def _axes(fig: Figure) -> list[Axes]:
    """The plotting axes (colour bars checked separately: their label is on one axis only)."""
    return [ax for ax in fig.get_axes() if ax.get_visible() and ax.get_label() != "<colorbar>"]


def _check_figure(fig: Figure, *, min_curves: int = 1) -> None:
    FigureCanvasAgg(fig).draw()  # the layout engine runs on draw; limits must hold after it
    legends = list(fig.legends) + [ax.get_legend() for ax in _axes(fig) if ax.get_legend() is not None]
    assert legends, "the figure has no legend"
    for ax in _axes(fig):
        for label in (ax.get_xlabel(), ax.get_ylabel()):
            assert UNIT.search(label), f"axis label {label!r} has no [unit]"
        x0, x1 = sorted(ax.get_xlim())
        y0, y1 = sorted(ax.get_ylim())
        curves = [(ln.get_label(), np.asarray(ln.get_xdata(), dtype=float), np.asarray(ln.get_ydata(), dtype=float))
                  for ln in ax.get_lines() if len(np.atleast_1d(ln.get_xdata())) > 2]
        curves += [(p.get_label(), *np.asarray(p.get_xy(), dtype=float).T) for p in ax.patches  # type: ignore[attr-defined]
                   if hasattr(p, "get_xy") and np.asarray(p.get_xy()).ndim == 2 and len(p.get_xy()) > 2]  # the arms, filled
        assert len(curves) >= min_curves
        for label, x, y in curves:
            ok = np.isfinite(x) & np.isfinite(y)
            tol_x, tol_y = 1e-9 * (x1 - x0), 1e-9 * (y1 - y0)
            assert np.all((x[ok] >= x0 - tol_x) & (x[ok] <= x1 + tol_x)), f"{label}: x outside {ax.get_xlabel()}"
            assert np.all((y[ok] >= y0 - tol_y) & (y[ok] <= y1 + tol_y)), f"{label}: y outside {ax.get_ylabel()}"


@pytest.fixture(scope="module")
def short_grasp():  # type: ignore[no-untyped-def]
    """The paper's closed loop for 0.4 s (the swing in: rho/rho_d from ~100 at the tip down to ~1)."""
    from contgrasp_core.control import paper_gains
    from contgrasp_core.objects import ROD_SCALE, ObjectSpec
    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop
    from contgrasp_core.scenario import PAPER

    obj = ObjectSpec.from_cli(None, None, ROD_SCALE)
    model = replace(PAPER.rod, n_elements=50)
    res = run_closed_loop(RodSystem(model, Obstacle(obj.boundary())), paper_gains(model, obj.radius),
                          ClosedLoopConfig(duration=0.4, dt=0.01, record_period=0.01))
    return res, obj


def test_fig4_labels_legend_and_every_curve_inside(short_grasp) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_core.figures.closed_loop import STATIC_LABEL, fig4_figure

    res, obj = short_grasp
    fig = fig4_figure(res, obj.boundary(), obj.radius)
    _check_figure(fig)
    arm, rho, alpha = _axes(fig)
    assert len(rho.get_lines()) >= 6 + 2  # six times, the static solution, the target
    labels = [ln.get_label() for ln in rho.get_lines()]
    assert STATIC_LABEL in labels and "eq. (20)" in STATIC_LABEL and "without the object" in STATIC_LABEL
    assert any("rho = \\rho_d" in lb for lb in labels)  # the rho/rho_d = 1 reference
    assert max(np.max(ln.get_ydata()) for ln in rho.get_lines()) > 10.0  # the early curves are not cut off at 3
    legend_texts = [t.get_text() for leg in [arm.get_legend(), *fig.legends] if leg for t in leg.get_texts()]
    assert sum(t.startswith("t = ") for t in legend_texts) >= 6  # the time shading is explained


@pytest.fixture(scope="module")
def drifting_object():  # type: ignore[no-untyped-def]
    """The holding law for 0.12 s with a free object set drifting at (5, 2) cm/s: it moves
    about 6 mm before the arm reaches it."""
    from contgrasp_core.control import paper_gains
    from contgrasp_core.control.hold_law import HoldController
    from contgrasp_core.objects import ROD_SCALE, ObjectSpec
    from contgrasp_core.rod.body import BodyState, ObjectDynamics
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop
    from contgrasp_core.scenario import PAPER, rod_system

    obj = ObjectSpec.from_cli(None, None, ROD_SCALE)
    model = replace(PAPER.rod, n_elements=20)
    system = rod_system(model, obj, ObjectDynamics("free"))
    start = replace(system.straight_state(), body=BodyState(np.zeros(3), np.array([0.05, 0.02, 0.0])))
    res = run_closed_loop(system, paper_gains(model, obj.radius), ClosedLoopConfig(duration=0.12, dt=0.01, record_period=0.01),
                          state=start, law=HoldController(model, obj.radius))
    return res, obj


def test_fig4_draws_a_moving_object_where_it_is_and_names_the_law(drifting_object) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_core.figures.closed_loop import fig4_figure, snapshot_indices

    res, obj = drifting_object
    assert res.law == "reactive" and res.object_q is not None and res.object_q.shape == (len(res.t), 3)
    assert res.object_q[-1][:2] == pytest.approx([0.05 * res.t[-1], 0.02 * res.t[-1]], rel=0.05)
    fig = fig4_figure(res, obj.boundary())
    _check_figure(fig)
    arm = _axes(fig)[0]
    assert arm.get_title().startswith("closed-loop grasp (reactive holding law")
    outlines = [ln for ln in arm.get_lines() if ln.get_linestyle() == "--"]
    idx = snapshot_indices(res, 6)
    assert len(outlines) == len(idx)
    for ln, k in zip(outlines, idx, strict=True):  # each snapshot's object about the centroid it had then
        centre = np.mean(np.c_[ln.get_xdata(), ln.get_ydata()][:-1], axis=0)
        assert centre == pytest.approx(np.array(obj.center) + res.object_q[k][:2], abs=1e-5)


def test_the_animation_moves_the_object(drifting_object, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The object's grey fill follows it: its pixels' centre moves right and up from the first frame to the last."""
    from PIL import Image

    from contgrasp_core.figures.closed_loop import animate

    res, obj = drifting_object
    animate(res, obj.boundary(), str(tmp_path / "a.gif"), frames=8)
    gif = Image.open(tmp_path / "a.gif")
    centres = []
    for frame in (0, gif.n_frames - 1):
        gif.seek(frame)
        rgb = np.asarray(gif.convert("RGB")).astype(int)
        rows, cols = np.nonzero(np.all(np.abs(rgb - 191) <= 2, axis=-1))  # matplotlib's "0.75" grey
        centres.append((cols.mean(), rows.mean()))
    assert centres[1][0] - centres[0][0] > 2 and centres[1][1] < centres[0][1]


@pytest.mark.skipif(not SAMPLE_BAG.exists(), reason="the sample bag is not in this checkout")
def test_run_figure_labels_legend_and_every_curve_inside() -> None:
    from contgrasp_core.figures.run import TIME_LABEL, build_run_figure
    from contgrasp_ros.recordings.analysis import history
    from contgrasp_ros.recordings.run_data import load_run

    run = load_run(SAMPLE_BAG)
    assert run.params is not None
    fig = build_run_figure({"history": history(run)}, run.params)
    _check_figure(fig)
    arm = _axes(fig)[0]
    legend = arm.get_legend()
    # live and bag-drawn figures label snapshots with the same thing: the header stamp (sim time)
    assert legend is not None and "header stamp" in legend.get_title().get_text() and "simulated time" in TIME_LABEL
    assert any(t.get_text().startswith("t = ") for t in legend.get_texts())
    # and the label is true of both messages drawn: the rod state and the contact state of one
    # step carry the same header stamp
    rod_t = dict(zip(run.rod.step.tolist(), run.rod.t.tolist(), strict=True))
    assert run.contact is not None
    pairs = [(rod_t[k], t) for k, t in zip(run.contact.step.tolist(), run.contact.t.tolist(), strict=True) if k in rod_t]
    assert pairs and all(a == b for a, b in pairs)


def test_kinematics_figure_labels_legend_curves_and_a_title_that_fits(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import contgrasp_core.figures.draw as draw
    from contgrasp_core.cli import main

    outline = Path(__file__).parent / "data" / "kidney_outline.csv"
    long_dir = tmp_path / ("a_rather_long_directory_name_" * 3)
    long_dir.mkdir()
    csv = long_dir / "kidney.csv"
    csv.write_text(outline.read_text())
    captured: list[Figure] = []
    real_save = draw.save
    monkeypatch.setattr(draw, "save", lambda fig, path, dpi=130: (captured.append(fig), real_save(fig, path, dpi))[1])
    assert main(["kinematics", "--outline", str(csv), "--rho0", "0.5", "--plot", str(tmp_path / "k.png"), "--json"]) == 0
    (fig,) = captured
    _check_figure(fig)
    assert "kidney.csv" in fig.get_suptitle().replace("\n", "")
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    box = fig._suptitle.get_window_extent(canvas.get_renderer())  # type: ignore[union-attr]
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width and box.y1 <= fig.bbox.height  # not cut off


@pytest.mark.parametrize("name", ["circle", "ellipse", "deformed"])
def test_fig2_labels_legend_and_every_curve_inside(name: str) -> None:
    """The curvature peak near the base (~10x the object's curvature) is shown, not clipped."""
    from contgrasp_core.figures.grasp import plot_grasp
    from contgrasp_core.optimal import paper_problem, solve

    result = solve(paper_problem(name, nodes=200))
    fig = plot_grasp(result, title=name)
    _check_figure(fig)
    kappa_axes = _axes(fig)[2]
    assert kappa_axes.get_ylim()[1] >= float(np.max(result.kappa))


@pytest.mark.heavy
def test_fig3_labels_legend_colour_bar_and_title() -> None:
    from contgrasp_core.figures.quality_map import quality_map_figure
    from contgrasp_core.objects import ObjectSpec
    from contgrasp_core.quality_map import MapSpec, quality_map

    qm = quality_map(MapSpec(ObjectSpec.parse("circle"), psi_steps=4, d_steps=2, nodes=40), executor="serial",
                     progress=False)
    fig = quality_map_figure(qm)
    _check_figure(fig)
    bars = [ax for ax in fig.get_axes() if ax.get_label() == "<colorbar>"]
    assert len(bars) == 3 and all(UNIT.search(ax.get_ylabel()) for ax in bars)
    assert fig.get_suptitle() == "grasp quality maps: circle:5"  # the object's text, not its repr


def test_fig3_of_a_single_distance_shows_its_poses() -> None:
    """A map of one distance (``--d-steps 1``) spans no area to shade: each panel shows its
    poses as coloured points, one per polar angle (before: a ValueError from the triangulation)."""
    from matplotlib.collections import PathCollection

    from contgrasp_core.figures.quality_map import quality_map_figure
    from contgrasp_core.objects import ObjectSpec
    from contgrasp_core.quality_map import MapSpec, quality_map

    qm = quality_map(MapSpec(ObjectSpec.parse("ellipse"), psi_steps=5, d_steps=1, nodes=40), executor="serial",
                     progress=False)
    fig = quality_map_figure(qm)
    _check_figure(fig)
    panels = [ax for ax in fig.get_axes() if ax.get_label() != "<colorbar>"]
    points = [c for ax in panels for c in ax.collections if isinstance(c, PathCollection)]
    assert len(points) == 3 and all(len(c.get_offsets()) == int((~np.isnan(qm.base[..., 0])).sum()) == 5 for c in points)


# --- readable figures and figures the code reproduces

FIGURES_DIR = Path(__file__).resolve().parents[1] / "docs" / "figures"
MIN_RGB_STEP = 0.35
"""Least Euclidean RGB distance (each channel in 0..1) between successive snapshot colours (and
between the final one and every other): the old Purples at 0.35..1.0 (run figure) and Blues (Fig. 4)
gave 0.17-0.21, a change of lightness only, so t = 0.15, 0.25 and 2.19 s read as one purple once
drawn translucent; turbo at 0.05..0.95 gives >= 0.47."""


def _snapshot_line_colours(ax: Axes) -> np.ndarray:
    return np.array([to_rgb(ln.get_color()) for ln in ax.get_lines() if ln.get_label().startswith("t = ")])


def _check_snapshot_colours(colours: np.ndarray) -> None:
    assert len(colours) >= 3
    steps = np.linalg.norm(np.diff(colours, axis=0), axis=1)
    assert steps.min() >= MIN_RGB_STEP, f"successive snapshot colours too close: {steps}"
    # the final snapshot is distinct from every other one
    assert np.linalg.norm(colours[:-1] - colours[-1], axis=1).min() >= MIN_RGB_STEP


def test_fig4_snapshot_colours_are_distinguishable_in_metres(short_grasp) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_core.figures.closed_loop import LENGTH_UNIT, SNAPSHOT_CMAP, fig4_figure, snapshot_colours

    res, obj = short_grasp
    fig = fig4_figure(res, obj.boundary(), obj.radius)
    arm, rho, _ = _axes(fig)
    colours = _snapshot_line_colours(rho)
    _check_snapshot_colours(colours)
    np.testing.assert_allclose(colours, snapshot_colours(len(colours))[:, :3])
    assert SNAPSHOT_CMAP == "turbo" and LENGTH_UNIT == "m"
    assert (arm.get_xlabel(), arm.get_ylabel()) == ("x [m]", "y [m]")
    # the arm is drawn in metres: the 20 cm arm spans less than 1 unit of the axes
    assert max(abs(v) for v in (*arm.get_xlim(), *arm.get_ylim())) < 1.0


@pytest.mark.skipif(not SAMPLE_BAG.exists(), reason="the sample bag is not in this checkout")
def test_run_figure_shares_fig4s_units_and_colour_map() -> None:
    from contgrasp_core.figures.closed_loop import LENGTH_UNIT, snapshot_colours
    from contgrasp_core.figures.run import build_run_figure
    from contgrasp_ros.recordings.analysis import history
    from contgrasp_ros.recordings.run_data import load_run

    run = load_run(SAMPLE_BAG)
    assert run.params is not None
    fig = build_run_figure({"history": history(run)}, run.params)
    arm, rho, _ = _axes(fig)
    assert (arm.get_xlabel(), arm.get_ylabel()) == (f"x [{LENGTH_UNIT}]", f"y [{LENGTH_UNIT}]")
    colours = _snapshot_line_colours(rho)
    _check_snapshot_colours(colours)
    np.testing.assert_allclose(colours, snapshot_colours(len(colours))[:, :3])  # Fig. 4's colours


def test_study_figure_has_readable_colour_bar_labels_and_whole_ranks() -> None:
    """The stiffness's symmetric log colour bar: no two tick labels overlap (those of 0 and of the
    linear part's edges did); the rank axes tick whole numbers only."""
    from contgrasp_core.figures.holding import study_figure
    from contgrasp_core.quality_map import MapSpec, quality_map

    qm = quality_map(MapSpec("circle", psi_steps=6, d_steps=3, nodes=40), executor="serial", optimise=False)
    rng = np.random.default_rng(1)
    rows = [{"key": f"grid:{i},{j}", "status": "ok", "stiffness_min": float(rng.choice([-1, 1]) * 10 ** rng.uniform(-1, 3)),
             "capacity_min": float(rng.uniform(0.1, 2.0)), "static_Q1": float(rng.uniform()), "Q1": float(rng.uniform())}
            for i in range(6) for j in range(3)]
    fig = study_figure(qm, rows)
    FigureCanvasAgg(fig).draw()
    (bar,) = [ax for ax in fig.get_axes() if ax.get_label() == "<colorbar>" and ax.get_ylabel() == "N/m"]
    boxes = sorted((t.get_window_extent() for t in bar.get_yticklabels() if t.get_text()), key=lambda b: b.y0)
    assert len(boxes) >= 5 and "0" in [t.get_text() for t in bar.get_yticklabels()]
    assert all(low.y1 <= high.y0 for low, high in zip(boxes[:-1], boxes[1:], strict=True)), [(b.y0, b.y1) for b in boxes]
    (ranks,) = [ax for ax in fig.get_axes() if ax.get_xlabel().startswith("rank")]
    for ticks, (lo, hi) in ((ranks.get_xticks(), ranks.get_xlim()), (ranks.get_yticks(), ranks.get_ylim())):
        shown = ticks[(ticks >= lo) & (ticks <= hi)]
        assert len(shown) >= 3 and np.all(shown == np.round(shown)), shown


def test_quality_history_has_units_no_axis_offsets_and_explains_the_settled_line(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_core.figures.run import CREEP_NOTE, quality_history_figure

    t = np.linspace(0.0, 2.2, 221)
    # values like the paper run's: Q1 ~ 4e-5 m^3, Q2 ~ 4e-7 m^5, Q3 ~ 4.4e-4, with small changes
    q = (4.2e-5 + 3e-6 * np.tanh(t), 3.2e-7 + 1.5e-7 * np.tanh(t), 4.8e-4 - 4e-5 * np.tanh(t))
    fig = quality_history_figure(t, q, str(tmp_path / "q.png"), settle_time=1.89, settle_rule=(0.002, 0.3))
    FigureCanvasAgg(fig).draw()
    axes = _axes(fig)
    assert len(axes) == 3
    for ax, unit in zip(axes, ("[cm$^3$]", "[cm$^5$]", "[-]"), strict=True):
        assert ax.get_ylabel().endswith(unit)
        assert ax.yaxis.get_offset_text().get_text() == "", ax.get_ylabel()
    labels = axes[0].get_legend_handles_labels()[1]
    assert "settled: every node slower than 2 mm/s for 0.3 s" in labels
    texts = [tx.get_text().replace("\n", " ") for tx in fig.texts]
    assert CREEP_NOTE in texts and "Q2" in CREEP_NOTE


def test_kinematics_title_keeps_numbers_whole_and_the_legend_off_the_object(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import contgrasp_core.figures.draw as draw
    from contgrasp_core.cli import main

    captured: list[Figure] = []
    real_save = draw.save
    monkeypatch.setattr(draw, "save", lambda fig, path, dpi=130: (captured.append(fig), real_save(fig, path, dpi))[1])
    assert main(["kinematics", "--object", "deformed", "--plot", str(tmp_path / "k.png"), "--json"]) == 0
    (fig,) = captured
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    title = fig.get_suptitle()
    for line in title.split("\n"):  # a line break only at a space, and never in front of a number
        assert line == line.strip() and not re.match(r"[-+(]?\d", line), title
    assert re.search(r"max discrepancy \d\.\de-?\d+", title)
    box = fig._suptitle.get_window_extent(renderer)  # type: ignore[union-attr]
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width
    arm = _axes(fig)[0]
    outline = max(arm.get_lines(), key=lambda ln: len(ln.get_xdata()))  # the object's closed outline (720 points)
    legends = [leg for leg in [arm.get_legend(), *fig.legends, *(sf.legends for sf in fig.subfigs)] if leg]
    flat = [leg for item in legends for leg in (item if isinstance(item, list) else [item])]
    legend = next(leg for leg in flat if "object" in [tx.get_text() for tx in leg.get_texts()])
    assert not legend.get_window_extent(renderer).overlaps(outline.get_window_extent(renderer))


def test_fig2_panels_reproduce_the_committed_images(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """``contgrasp figures --no-maps`` (the three Fig. 2 solves, ~1 s) redraws the committed
    panels. Tolerance: RMS 2 of 255 grey levels (compare_images): matplotlib's own test tolerance
    scale, which absorbs anti-aliasing and freetype differences between machines (<1 here: the
    images are identical on the machine that made them), while a moved curve or marker fails
    (the Fig. 3 circle's optimum moving across the panel gave RMS 8.3)."""
    from matplotlib.testing.compare import compare_images

    from contgrasp_core.cli import main

    assert main(["figures", "--no-maps", "--out", str(tmp_path), "--json"]) == 0
    for name in ("circle", "ellipse", "deformed"):
        expected = FIGURES_DIR / f"fig2_{name}.png"
        result = compare_images(str(expected), str(tmp_path / expected.name), tol=2.0, in_decorator=True)
        assert result is None, result


def test_quality_map_ties_go_to_the_smallest_polar_angle() -> None:
    from contgrasp_core.quality_map import TIE_RTOL, best_grid_pose

    grid = np.full((6, 3), -np.inf)
    grid[4, 0] = 1.0
    grid[2, 1] = 1.0 - 0.5 * TIE_RTOL  # a tie (within the tolerance), at a smaller psi
    grid[1, 2] = 0.5
    assert best_grid_pose(grid) == (2, 1)
    grid[4, 0] = 1.0 + 2 * TIE_RTOL  # better beyond the tolerance: no tie
    assert best_grid_pose(grid) == (4, 0)
    grid[2, 0] = grid[4, 0]  # same psi row: the smaller d
    grid[2, 1] = grid[4, 0]
    assert best_grid_pose(grid) == (2, 0)


@pytest.mark.heavy
def test_circle_map_optimum_is_at_the_smallest_polar_angle_on_every_run() -> None:
    """A circle's map is flat along psi up to the solves' last digits: the optimum reported is
    the pose at psi = 0 (the tie rule), not wherever those digits peak."""
    from contgrasp_core.quality_map import MapSpec, quality_map

    qm = quality_map(MapSpec("circle", psi_steps=6, d_steps=2, nodes=60), executor="serial", progress=False)
    for opt in qm.optimum.values():
        assert (opt["psi"], opt["d"]) == (0.0, 3.0)
        assert (opt["base"]["x"], opt["base"]["y"]) == pytest.approx((8.0, 0.0), abs=1e-12)


def test_committed_fig3_shows_the_documented_optimum() -> None:
    """The metadata ``contgrasp figures`` writes beside Fig. 3 (the maps take minutes: not redrawn
    here): the circle's optimum is at psi = 0, base (8, 0) (docs/quality.md), on the default grid;
    the ellipse's is the first of its two point-symmetric optima (psi < pi)."""
    import json

    circle = json.loads((FIGURES_DIR / "fig3_circle.json").read_text())
    assert (circle["psi_steps"], circle["d_steps"]) == (48, 11)
    for opt in circle["optimum"].values():
        assert (opt["psi"], opt["d"]) == (0.0, 3.0)
        assert (opt["base"]["x"], opt["base"]["y"]) == pytest.approx((8.0, 0.0), abs=1e-9)
    ellipse = json.loads((FIGURES_DIR / "fig3_ellipse.json").read_text())
    assert all(0.0 <= opt["psi"] < np.pi for opt in ellipse["optimum"].values())


def test_every_law_has_a_figure_title() -> None:
    """Fig. 4 and its animation name the law that ran: a title for each law of the loop (a new law's
    ``--plot`` once failed with a ``KeyError`` on its name)."""
    from contgrasp_core.control.hold_law import LAWS
    from contgrasp_core.figures.closed_loop import LAW_TITLES

    assert set(LAW_TITLES) == set(LAWS)
