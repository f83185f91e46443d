"""One check of a scenario's start before any run: the straight arm must start
outside the object and the object must be within its reach
(:func:`contgrasp_core.scenario.check_start`). ``contgrasp simulate``, ``contgrasp hold``,
the scenario model (the holding study, the launcher) and the simulator node (its start-up test
is in tests/test_node_faults.py) all refuse an impossible start with one line naming the cause,
instead of simulating it "successfully" or failing later with a Newton message."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.cli import main as cli_main
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.objects import ROD_SCALE, ObjectSpec
from contgrasp_core.scenario import PAPER, check_start

KIDNEY = Path(__file__).parent / "data" / "kidney_outline.csv"


def _cli(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str]:
    """``contgrasp ARGV`` in-process: (exit code, the one stderr line; nothing on stdout)."""
    capsys.readouterr()
    code = cli_main(argv)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert out == "" and len(lines) == 1, (argv, out, err)
    return code, lines[0]


def _kidney(tmp_path: Path, scale: float) -> Path:
    """The test outline (paper units, around the origin) at ``scale`` m per paper unit, centred
    at the rod scenario's object centre (8, 8) cm; 0.005 is the rod scenario's size."""
    pts = np.loadtxt(KIDNEY, delimiter=",", skiprows=2) * scale + 0.08
    path = tmp_path / f"kidney_x{scale:g}.csv"
    np.savetxt(path, pts, delimiter=",", header="x, y", comments="")
    return path


# ------------------------------------------------------------------ the check itself
@pytest.mark.parametrize("obj", [PAPER.object, ObjectSpec("ellipse", (0.03, 0.02), (0.08, 0.08)),
                                 ObjectSpec("deformed", (0.025, 0.15, 3.0, 0.0), (0.08, 0.08))],
                         ids=["paper circle", "ellipse", "deformed"])
def test_the_paper_objects_pass(obj: ObjectSpec) -> None:
    check_start(PAPER.rod, obj)
    assert PAPER.with_object(obj).object == obj


def test_the_kidney_outline_in_metres_passes(tmp_path: Path) -> None:
    check_start(PAPER.rod, ObjectSpec.from_outline(_kidney(tmp_path, 0.005)))


def test_an_object_across_the_straight_arm_is_refused() -> None:
    with pytest.raises(InvalidParameterError) as info:
        PAPER.with_object(ObjectSpec("circle", (0.5,), (0.08, 0.08)))
    msg = str(info.value)
    assert msg.startswith("the arm starts inside the object: its straight start at base (0, 0) heading 0 rad passes "
                          "0.426 m inside the object (circle of radius 0.5 m)"), msg
    assert "move the base or shrink the object" in msg and "in metres" not in msg and "\n" not in msg


def test_a_long_bar_beside_the_arm_is_a_valid_start(capsys: pytest.CaptureFixture[str]) -> None:
    """``ellipse:1`` at the rod scale is ellipse:1,0.02 (the omitted semi-axis from the scale): a
    2 m bar whose near side runs 6 cm above the straight arm. The arm is outside it and within
    reach of it, so the start is valid (the fuzz once listed it as bad input), while the same
    bar turned across the arm is refused."""
    bar = ObjectSpec.parse("ellipse:1", ROD_SCALE)
    assert bar.params == (1.0, 0.02)
    check_start(PAPER.rod, bar)
    code, line = _cli(capsys, ["simulate", "--object", "ellipse:0.02,1", "--duration", "0.1"])
    assert code == 2 and line.startswith("contgrasp simulate: error: the arm starts inside the object"), line


def test_the_arm_surface_counts_not_only_its_centreline() -> None:
    """A circle whose boundary passes 5 mm from the centreline at the base, where the arm is
    1 cm thick: the centreline is outside, the surface is not."""
    obj = ObjectSpec("circle", (0.02,), (0.0, 0.025))
    with pytest.raises(InvalidParameterError, match=r"passes 0\.005 m inside the object"):
        check_start(PAPER.rod, obj)
    check_start(PAPER.rod, replace(obj, center=(0.0, 0.0305)))  # (clear of the surface by 0.5 mm)


@pytest.mark.parametrize("change", ["object", "base"])
def test_an_object_out_of_reach_is_refused(change: str) -> None:
    """A small circle 1.39 m away from the base: the arm (0.2 m) cannot reach it, whether the
    object or the base was moved."""
    with pytest.raises(InvalidParameterError) as info:
        if change == "object":
            PAPER.with_object(ObjectSpec("circle", (0.025,), (1.0, 1.0)))
        else:
            replace(PAPER, rod=replace(PAPER.rod, base_position=(-0.92, -0.92)))
    msg = str(info.value)
    assert msg.startswith("the object is out of the arm's reach: the base (") and " is 1.39 m from the object" in msg, msg
    assert "the arm is 0.2 m long" in msg


def test_with_object_checks_the_new_object_with_the_new_rod() -> None:
    """The holding study and ``hold --base`` move the base with the object: the paper's base
    would start inside this ellipse, the new one does not."""
    obj = ObjectSpec("ellipse", (0.1, 0.02), (0.08, 0.0))
    with pytest.raises(InvalidParameterError, match="inside the object"):
        PAPER.with_object(obj)
    rod = replace(PAPER.rod, base_position=(0.0, -0.04))
    assert PAPER.with_object(obj, rod=rod).rod.base_position == (0.0, -0.04)


# ------------------------------------------------------------------ the commands
def test_simulate_refuses_a_start_inside_the_object(capsys: pytest.CaptureFixture[str]) -> None:
    code, line = _cli(capsys, ["simulate", "--object", "circle:0.5", "--json"])
    assert code == 2 and line.startswith("contgrasp simulate: error: the arm starts inside the object: "), line
    assert "0.426 m inside the object (circle of radius 0.5 m)" in line


def test_hold_refuses_a_start_inside_the_object_at_once(capsys: pytest.CaptureFixture[str]) -> None:
    t0 = time.perf_counter()
    code, line = _cli(capsys, ["hold", "--object", "circle:0.5", "--json"])
    assert code == 2 and line.startswith("contgrasp hold: error: the arm starts inside the object: "), line
    assert time.perf_counter() - t0 < 5.0  # (it failed after 13 s of simulation with a Newton message)


@pytest.mark.parametrize("scale", [0.25, 1.0], ids=["x50", "paper units"])
def test_an_outline_in_the_wrong_units_asks_about_metres(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        scale: float) -> None:
    """The kidney 50 times its rod-scenario size, and in the paper's dimensionless units
    (numbers ~5 while the arm is 0.2 m long): refused, asking whether it is in metres."""
    code, line = _cli(capsys, ["simulate", "--outline", str(_kidney(tmp_path, scale)), "--json", "--nodes", "21"])
    assert code == 2 and line.startswith("contgrasp simulate: error: the arm starts inside the object: "), line
    assert "is the outline in metres? (it is " in line and "the arm is 0.2 m long)" in line


# ------------------------------------------------------------------ the launcher
def _no_graph(*_a: object, **_k: object) -> None:
    raise AssertionError("the launcher started the graph of an impossible scenario")


@pytest.mark.parametrize("how", ["object", "params"])
def test_the_launcher_refuses_before_any_node_starts(how: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """``--object circle:0.5``, or a parameter file whose base lies inside the default object:
    exit 2 and one line, the graph never started."""
    pytest.importorskip("yaml")
    import yaml

    import contgrasp_ros.launcher.graph_run
    from contgrasp_ros.launcher import cli as launcher

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", _no_graph)
    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR"):  # (the launcher sets them)
        monkeypatch.setenv(var, "0")
    if how == "object":
        argv = ["--object", "circle:0.5", "--no-record"]
    else:
        data = yaml.safe_load(launcher.default_params_file().read_text())
        data["/**"]["ros__parameters"].update(base_x=0.08, base_y=0.08)
        params = tmp_path / "params.yaml"
        params.write_text(yaml.safe_dump(data))
        argv = ["--params", str(params), "--no-record"]
    capsys.readouterr()
    assert launcher.main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("contgrasp-launch: error: the arm starts inside the object: "), err
