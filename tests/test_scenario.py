"""One scenario model and one object syntax: the packaged YAML, the nodes' defaults and every
command that takes an object agree; a user's own outline runs through all of them."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.cli import main as cli_main
from contgrasp_core.errors import InvalidBoundaryError, InvalidParameterError
from contgrasp_core.objects import FIG2_SCALE, ROD_SCALE, ObjectSpec
from contgrasp_core.scenario import NODES, PAPER, Scenario
from contgrasp_ros.launcher.cli import default_params_file, load_params
from contgrasp_ros.launcher.graph import known_parameters

KIDNEY = Path(__file__).parent / "data" / "kidney_outline.csv"


def kidney_in_metres(tmp_path: Path) -> Path:
    """The test outline at the rod scenario's scale: 5 mm per paper unit, centred at (8, 8) cm."""
    pts = np.loadtxt(KIDNEY, delimiter=",", skiprows=2) * 0.005 + 0.08
    path = tmp_path / "kidney_m.csv"
    np.savetxt(path, pts, delimiter=",", header="x, y", comments="")
    return path


# ------------------------------------------------------------------ the scenario model
def test_packaged_yaml_is_the_paper_scenario() -> None:
    """config/default.yaml holds exactly PAPER's values (and nothing of the scenario differs)."""
    yaml_params = load_params(default_params_file())
    for node in NODES:
        want = PAPER.node_parameters(node)
        got = {k: yaml_params[node][k] for k in want}
        assert got == want, node


def test_scenario_round_trips_through_ros_parameters() -> None:
    assert Scenario.from_ros_parameters(PAPER.to_ros_parameters()) == PAPER
    ellipse = PAPER.with_object(ObjectSpec("ellipse", (0.03, 0.02), (0.07, 0.09), 0.4))
    back = Scenario.from_ros_parameters(ellipse.to_ros_parameters())
    assert back.object == ellipse.object and back.rod == ellipse.rod and back.loop == ellipse.loop
    assert back.gains.object_radius == pytest.approx(np.sqrt(0.03 * 0.02))  # the nominal radius, made explicit


def test_object_motion_round_trips_through_ros_parameters() -> None:
    """The object's dynamics and the scripted disturbance are the simulator's parameters; the
    paper's fixed object without a disturbance is the packaged default."""
    from contgrasp_core.rod.body import ObjectDynamics
    from contgrasp_core.rod.disturbance import Disturbance

    sim = PAPER.to_ros_parameters()["rod_simulator"]
    assert sim["object_mode"] == "fixed" and sim["disturbance_kind"] == "" and PAPER.disturbance is None
    for dynamics, disturbance in [
        (ObjectDynamics("spring", 12.0, 0.05, 2e-5, (30.0, 20.0, 0.5), (0.2, 0.1, 0.01)), Disturbance("pulse", (0.1, -0.2, 1e-3), 0.5, 0.2)),
        (ObjectDynamics("free", areal_density=3.0), Disturbance("ramp", (0.0, 1.0, 0.0), 0.0, 1.0)),
        (ObjectDynamics("free", mass=0.2), None),
    ]:
        scenario = replace(PAPER, dynamics=dynamics, disturbance=disturbance)
        assert Scenario.from_ros_parameters(scenario.to_ros_parameters()) == scenario


def test_paper_scenario_is_the_reference_run() -> None:
    """PAPER is the scenario tests/golden/reference.json was computed for (before the model existed)."""
    ref = json.loads((Path(__file__).parent / "golden" / "reference.json").read_text())["lockstep_paper_run"]
    from contgrasp_core.rod.session import run_sampled

    session = run_sampled(replace(PAPER, loop=replace(PAPER.loop, duration=0.02)))
    assert session.k == 10
    # the first 10 steps of the reference run end where the reference's base moved: a check
    # that the model (rod, object, gains, tolerance) is the one the reference used
    assert ref["k"] == 1097
    x = session.observe().x
    assert np.all(np.isfinite(x)) and x.shape == (PAPER.rod.n_elements + 1, 2)


@pytest.mark.parametrize("node", ["rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality"])
def test_node_without_parameter_file_runs_the_paper_scenario(node: str, ros_context) -> None:  # type: ignore[no-untyped-def]
    """A node started with no parameter file declares every value config/default.yaml sets."""
    pytest.importorskip("contgrasp_msgs.msg")
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor
    from contgrasp_ros.nodes.grasp_controller import GraspController
    from contgrasp_ros.nodes.grasp_quality import GraspQualityNode
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    cls = {"rod_simulator": RodSimulator, "boundary_sensor": BoundarySensor, "grasp_controller": GraspController,
           "grasp_quality": GraspQualityNode}[node]
    n = cls(context=ros_context)
    try:
        import yaml

        yaml_params = load_params(default_params_file())[node]
        own = yaml.safe_load(default_params_file().read_text())[node]["ros__parameters"]
        assert all(n.has_parameter(k) for k in own)  # everything the file sets for this node exists
        declared = {k: v for k, v in yaml_params.items() if n.has_parameter(k)}
        assert declared.keys() >= own.keys()
        assert {k: n.get_parameter(k).value for k in declared} == declared
        assert set(n.list_parameters([], 0).names) <= known_parameters(node)  # what a parameter file may set for it
        if node == "rod_simulator":
            assert n.model == PAPER.rod and n.config == PAPER.loop
            assert n.boundary.kind == "circle" and n.boundary.params["R"] == 0.025
    finally:
        n.destroy_node()


# ------------------------------------------------------------------ the object syntax
def test_object_text_syntax_and_defaults() -> None:
    assert ObjectSpec.parse("circle") == ObjectSpec("circle", (5.0,))
    assert ObjectSpec.parse("ellipse:6", FIG2_SCALE).params == (6.0, 4.0)
    assert ObjectSpec.parse("circle", ROD_SCALE) == PAPER.object
    assert ObjectSpec.parse("deformed:0.02", ROD_SCALE).params == (0.02, 0.15, 3.0, 0.0)
    for spec in (ObjectSpec.parse("deformed"), ObjectSpec("ellipse", (3.0, 1.0), (1.0, 2.0), 0.3)):
        assert ObjectSpec.from_dict(json.loads(json.dumps(spec.to_dict()))) == spec
    # the boundary a spec builds is the shape it names
    b = ObjectSpec.parse("ellipse:8,4").boundary()
    from scipy.special import ellipe

    assert b.length == pytest.approx(4 * 8.0 * ellipe(1 - (4.0 / 8.0) ** 2), rel=1e-9)  # perimeter 4 a E(e^2)


@pytest.mark.parametrize("text,match", [
    ("square", "unknown object"), ("circle:x", "must be numbers"), ("circle:1,2", "at most 1"),
    ("deformed:5,0.1,2.5", "integer"), ("circle:-1", "R"), ("outline", "--outline FILE.csv"), ("", "NAME"),
])
def test_bad_object_text_is_refused(text: str, match: str) -> None:
    with pytest.raises(InvalidParameterError, match=match):
        ObjectSpec.parse(text)


def test_outline_is_read_as_given_and_closed_implicitly(tmp_path: Path) -> None:
    spec = ObjectSpec.from_outline(KIDNEY)
    b = spec.boundary()
    s = np.linspace(0.0, b.length, 800, endpoint=False)
    assert b.curvature(s).min() < -0.5 < 0.5 < b.curvature(s).max()  # non-convex
    rows = np.loadtxt(KIDNEY, delimiter=",", skiprows=2)
    # every row is on the curve (an interpolating spline), also without the repeated first row
    assert np.abs(b.project(rows).distance).max() < 1e-9
    open_file = tmp_path / "open.csv"
    np.savetxt(open_file, rows[:-1], delimiter=",")
    b2 = ObjectSpec.from_outline(open_file).boundary()
    assert b2.length == pytest.approx(b.length, rel=1e-12)


def _malformed(tmp_path: Path) -> dict[str, Path]:
    cases = {
        "few": "0,0\n1,0\n1,1\n0,0\n",
        "crossing": "0,0\n2,2\n2,0\n0,2\n-1,1\n0,0\n",
        "nan": "0,0\n1,0\nnan,1\n0,1\n-1,0.5\n0,0\n",
        "columns": "0,0,1\n1,0,1\n1,1,1\n0,1,1\n-1,0.5,1\n0,0,1\n",
    }
    out = {}
    for name, text in cases.items():
        out[name] = tmp_path / f"{name}.csv"
        out[name].write_text(text)
    return out


def test_malformed_outlines_are_refused(tmp_path: Path) -> None:
    for name, path in _malformed(tmp_path).items():
        with pytest.raises(InvalidBoundaryError):
            ObjectSpec.from_outline(path)
        assert name


# ------------------------------------------------------------------ every command takes it
def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli_main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_user_outline_through_kinematics_grasp_and_quality_map(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = _run(["kinematics", "--outline", str(KIDNEY), "--json", "--nodes", "101"], capsys)
    assert code == 0, err
    k = json.loads(out)
    assert k["object"].startswith("outline:") and k["max_discrepancy"] < 1e-6
    code, out, err = _run(["grasp", "--outline", str(KIDNEY), "--json", "--nodes", "100"], capsys)
    assert code == 0, err
    g = json.loads(out)
    assert g["converged"] and g["constraints"]["ok"]
    code, out, err = _run(["quality-map", "--outline", str(KIDNEY), "--json", "--psi-steps", "4", "--d-steps", "2",
                           "--nodes", "60", "--executor", "serial", "--no-optimise"], capsys)
    assert code == 0, err
    q = json.loads(out)
    assert q["object"].startswith("outline:") and q["n_valid"] >= 1


def test_user_outline_through_simulate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = _run(["simulate", "--outline", str(kidney_in_metres(tmp_path)), "--json", "--duration", "0.3",
                           "--nodes", "31"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert s["sim_time_s"] == pytest.approx(0.3) and np.all(np.isfinite(s["final"]["x"]))


@pytest.mark.parametrize("command", [["kinematics"], ["grasp"], ["quality-map", "--executor", "serial"], ["simulate"]])
def test_malformed_outline_is_one_line_and_exit_2(command: list[str], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    for path in _malformed(tmp_path).values():
        code, out, err = _run([*command, "--outline", str(path)], capsys)
        assert code == 2 and out == ""
        assert len(err.strip().splitlines()) == 1 and "error:" in err
    code, _, err = _run([*command, "--object", "square"], capsys)
    assert code == 2 and "unknown object" in err


def test_launcher_refuses_a_malformed_outline(tmp_path: Path) -> None:
    bad = _malformed(tmp_path)["crossing"]
    out = subprocess.run([sys.executable, "-m", "contgrasp_ros.launcher.cli", "--outline", str(bad), "--no-record"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1 and "crosses itself" in out.stderr


@pytest.mark.heavy
def test_user_outline_through_the_ros_graph(tmp_path: Path) -> None:
    """contgrasp-launch --outline: the simulator gets the outline through its parameters, the
    sensor and the quality node through the object message; the graph equals the core loop
    with the same object."""
    pytest.importorskip("contgrasp_msgs.msg")
    import yaml

    from conftest import fresh_domain_id
    from contgrasp_core.rod.session import run_sampled

    outline = kidney_in_metres(tmp_path)
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = 20
    data["rod_simulator"]["ros__parameters"]["duration"] = 0.1
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    out = subprocess.run([sys.executable, "-m", "contgrasp_ros.launcher.cli", "--outline", str(outline), "--params", str(params),
                          "--no-record", "--json", "--domain-id", str(fresh_domain_id())],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    summary = json.loads(out.stdout)
    assert summary["missed_deadlines"] == 0 and summary["final_quality"] is not None
    scenario = Scenario.from_ros_parameters(load_params(params)).with_object(ObjectSpec.from_outline(outline))
    obs = run_sampled(scenario).observe()
    assert summary["steps"] == obs.k
    np.testing.assert_array_equal(summary["final"]["x"], obs.x[:, 0])
    np.testing.assert_array_equal(summary["final"]["y"], obs.x[:, 1])


def test_a_fine_outline_of_the_circle_grasps_as_the_circle(tmp_path: Path) -> None:
    """The launcher's quality node takes its wrench reference from the object: an outline's is its
    centroid, not its file's origin (0, 0), 11 cm away, which turned Q1 by 1.5 % and Q3 by 3 %
    while Q2 (det W, reference-free) agreed. The same arm wrapped around the circle and around
    its 72-point outline then gives the same Q1-Q3."""
    from contgrasp_core.arm import ArmShape
    from contgrasp_core.contact import sense
    from contgrasp_core.quality import quality_of_state
    from contgrasp_ros.launcher.graph import launch_overrides

    t = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    path = tmp_path / "circle72.csv"
    np.savetxt(path, np.c_[0.08 + 0.025 * np.cos(t), 0.08 + 0.025 * np.sin(t)], delimiter=",")
    outline, circle = ObjectSpec.from_outline(path), ObjectSpec.from_cli("circle", None, ROD_SCALE)
    params = load_params(default_params_file())
    for obj in (outline, circle):
        quality = launch_overrides(params, obj)["grasp_quality"]
        assert (quality["reference_x"], quality["reference_y"]) == pytest.approx((0.08, 0.08), abs=1e-9)
    s = np.linspace(0.0, 0.12, 61)  # an arm 1 mm off the circle's surface over 275 degrees
    phi = -np.pi / 2 + s / 0.026
    arm = ArmShape(s, np.c_[0.08 + 0.026 * np.cos(phi), 0.08 + 0.026 * np.sin(phi)], phi + np.pi / 2)
    q = [quality_of_state(sense(arm, obj.boundary(), 0.0015, tol=0.0005), obj.boundary(),
                          ref=Scenario.from_ros_parameters({**params, **launch_overrides(params, obj)}).reference)
         for obj in (outline, circle)]
    assert q[0].Q1 == pytest.approx(q[1].Q1, rel=1e-3) and q[0].Q3 == pytest.approx(q[1].Q3, rel=1e-3) and q[1].Q1 > 0


def test_an_outline_travels_in_the_object_message_exactly(tmp_path: Path) -> None:
    """The object message of a user's outline carries its points: the receiver rebuilds the
    sender's curve bit for bit (a resampled spline would differ by ~1e-11 m)."""
    pytest.importorskip("contgrasp_msgs.msg")
    from std_msgs.msg import Header

    from contgrasp_ros.plumbing.convert import boundary_from_msg, boundary_to_msg

    for smoothing in (0.0, 1e-4):
        sent = ObjectSpec.from_outline(kidney_in_metres(tmp_path)).boundary()
        if smoothing:
            from contgrasp_core.boundary import from_points

            sent = from_points(np.asarray(sent.params["points"]), closed=True, smoothing=smoothing)
        got = boundary_from_msg(boundary_to_msg(sent, Header()))
        s = np.linspace(0.0, sent.length, 97)
        assert got.length == sent.length
        np.testing.assert_array_equal(got.point(s), sent.point(s))
        np.testing.assert_array_equal(got.curvature(s), sent.curvature(s))


def test_a_scenario_around_another_object_takes_its_wrench_reference(tmp_path: Path) -> None:
    """``with_object`` (``contgrasp hold``, the study's poses): the paper's reference (0.08, 0.08),
    its circle's centre, follows the new object (an outline elsewhere: its centroid; it stayed at
    (0.08, 0.08)); a reference set apart from the object stays."""
    t = np.linspace(0.0, 2.0 * np.pi, 90, endpoint=False)
    path = tmp_path / "far.csv"
    np.savetxt(path, np.c_[0.09 + 0.02 * np.cos(t), 0.07 + 0.02 * np.sin(t)], delimiter=",")
    moved = PAPER.with_object(ObjectSpec.from_outline(path))
    assert moved.reference == pytest.approx((0.09, 0.07), abs=1e-9)
    chosen = replace(PAPER, sensing=replace(PAPER.sensing, reference=(0.1, 0.0)))
    assert chosen.with_object(ObjectSpec.from_outline(path)).reference == (0.1, 0.0)
