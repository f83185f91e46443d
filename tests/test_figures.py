"""The figure package draws with matplotlib's object API and never touches the backend."""

from __future__ import annotations

import subprocess
import sys


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


# --- what a reviewer checks on every figure (issue 19): labelled axes with units, a legend, and
# every curve inside the axes (no clipped data)

import re  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
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


@pytest.mark.skipif(not SAMPLE_BAG.exists(), reason="the sample bag is not in this checkout")
def test_run_figure_labels_legend_and_every_curve_inside() -> None:
    from contgrasp_core.figures.run import TIME_LABEL, build_run_figure
    from contgrasp_ros.recordings.analysis import history, load_run

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
