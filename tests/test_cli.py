"""The ``contgrasp`` command: JSON output, plots, and one-line errors with exit code 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.cli import main

ROOT = Path(__file__).resolve().parents[1]
KIN_KEYS = {"max_discrepancy", "s", "rho", "alpha", "s_o", "x", "y", "theta", "kappa", "discrepancy"}


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    exe = os.path.join(os.path.dirname(sys.executable), "contgrasp")
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=300)


@pytest.mark.heavy
@pytest.mark.parametrize("obj", ["circle", "ellipse", "deformed"])
def test_kinematics_json_and_plot(obj: str, tmp_path) -> None:  # type: ignore[no-untyped-def]
    png = tmp_path / f"{obj}.png"
    proc = run_cli("kinematics", "--object", obj, "--json", "--plot", str(png))
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)  # exactly one JSON object on stdout
    assert KIN_KEYS <= out.keys()
    assert out["max_discrepancy"] < 1e-6
    assert len(out["s"]) == len(out["rho"]) == len(out["x"]) == out["nodes"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_kinematics_user_outline_and_constant_profile(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    th = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    csv = tmp_path / "blob.csv"
    csv.write_text("x,y\n" + "\n".join(f"{3 * np.cos(t)},{2 * np.sin(t)}" for t in th))
    # the outline does not repeat its first point: it is closed implicitly (one object syntax everywhere)
    code = main(["kinematics", "--outline", str(csv), "--rho0", "0.5", "--alpha0", "1.5708",
                 "--length", "3", "--curvature", "parallel", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["max_discrepancy"] < 1e-6
    np.testing.assert_allclose(out["rho"], 0.5, atol=1e-4)


@pytest.mark.parametrize(
    "args,needle",
    [
        (["kinematics", "--alpha0", "3.5"], "(0, pi)"),
        (["kinematics", "--rho0", "0"], "rho = 0"),
        (["kinematics", "--nodes", "1"], "nodes"),
        (["kinematics", "--curvature", "wobbly"], "unknown curvature profile"),
        (["kinematics", "--curvature", "const:0", "--alpha0", "0.5", "--length", "20"], "left the admissible region"),
        (["kinematics", "--object", "points"], "unknown object"),
        (["kinematics", "--object", "circle", "--outline", "x.csv"], "not allowed with argument"),
    ],
)
def test_bad_input_is_one_line_exit_2(args: list[str], needle: str) -> None:
    proc = run_cli(*args)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert needle in proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(("argv", "line"), [
    (["simulate", "--duration", "0.01", "--nodes", "11", "--squeeze", "0.001", "--depth-gain", "5"],
     "contgrasp simulate: error: --squeeze, --depth-gain do nothing under --law paper: they need --law hold or reactive"),
    (["hold", "--nodes", "11", "--hold-gain", "10"],
     "contgrasp hold: error: --hold-gain does nothing under --law paper: it needs --law hold or reactive"),
])
def test_the_holding_laws_options_under_the_papers_law_are_refused(argv: list[str], line: str,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """The paper's law ignores them: given, they would pass silently."""
    capsys.readouterr()
    assert main(argv) == 2
    assert capsys.readouterr().err.splitlines() == [line]


@pytest.mark.parametrize("solver", ["fast", "forward-backward"])
def test_grasp_json_histories_have_an_entry_per_iteration(solver: str, capsys: pytest.CaptureFixture[str]) -> None:
    """``cost_history`` and ``residual_history`` (docs/cli.md): the starting iterate and one
    entry after each iteration but the fast solver's SQP steps, whose end is the start. The
    sweep stopped by its limit is no solution: exit 1, its result printed first, then one line."""
    capsys.readouterr()
    code = main(["grasp", "--json", "--nodes", "120", "--solver", solver, "--max-iterations", "20"])
    printed = capsys.readouterr()
    assert code == (0 if solver == "fast" else 1), printed.err
    if solver == "forward-backward":
        assert printed.err.splitlines() == ["contgrasp grasp: error: no optimal grasp: iteration limit 20 reached"]
    out = json.loads(printed.out)
    entries = out["iterations"] - out["sqp_steps"] + 1
    assert len(out["cost_history"]) == len(out["residual_history"]) == entries
    assert out["cost_history"][-1] == out["cost"]
    if solver == "fast":
        assert out["sqp_steps"] >= 1 and out["residual_history"][-1] == out["residual"]
    else:
        assert out["sqp_steps"] == 0 and out["iterations"] == 20


def test_loading_a_missing_quality_map_names_the_missing_file(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:  # type: ignore[no-untyped-def]
    """``--load FILE``: FILE.npz and FILE.json; the first missing one is named, with no exception's class."""
    base = tmp_path / "map"
    hint = "(a map is FILE.npz with FILE.json beside it, as --out writes them)"
    for present, missing in (((), "map.npz"), ((".npz",), "map.json")):
        for suffix in present:
            base.with_suffix(suffix).write_bytes(b"")
        capsys.readouterr()
        assert main(["quality-map", "--load", str(base)]) == 2
        assert capsys.readouterr().err.splitlines() == [
            f"contgrasp quality-map: error: cannot load quality map {base}: no file {tmp_path / missing} {hint}"]


def test_argparse_usage_error_is_exit_2() -> None:
    proc = run_cli("kinematics", "--nodes", "many")
    assert proc.returncode == 2
    assert "invalid int value" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("header", ["", "s,kappa\n", "# the profile\ns,kappa\n"])
def test_a_curvature_file_may_have_a_header_as_an_outline_may(tmp_path, header: str) -> None:  # type: ignore[no-untyped-def]
    """An ``s,kappa`` header is taken, as outline files take one (it was refused)."""
    from contgrasp_core.boundary import circle
    from contgrasp_core.cli.kinematics import curvature_profile
    from contgrasp_core.errors import InvalidParameterError

    csv = tmp_path / "kappa.csv"
    csv.write_text(header + "\n".join(f"{s:.3f},{0.5 + s:.3f}" for s in np.linspace(0.0, 2.0, 21)))
    s = np.linspace(0.0, 2.0, 9)
    np.testing.assert_allclose(curvature_profile(str(csv), circle(1.0), s, 0.5, 0.0), 0.5 + s)
    csv.write_text("s,kappa\n0,1\nnot,numbers\n")  # garbage after the data is still an error
    with pytest.raises(InvalidParameterError, match="cannot parse curvature file"):
        curvature_profile(str(csv), circle(1.0), s, 0.5, 0.0)


def test_a_grasp_that_is_no_solution_exits_1_after_its_result(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The kidney outline given in millimetres instead of paper units (an object a thousand
    times the arm): the solver stops at its limit far from a solution. Before, exit 0 with
    ``converged: False`` as the only sign; now the result is printed, then one line, exit 1."""
    kidney = np.loadtxt(ROOT / "tests" / "data" / "kidney_outline.csv", delimiter=",", skiprows=2)
    outline = tmp_path / "kidney_mm.csv"
    np.savetxt(outline, kidney * 1000.0, delimiter=",", header="x, y", comments="")
    capsys.readouterr()
    assert main(["grasp", "--outline", str(outline), "--nodes", "60", "--json"]) == 1
    printed = capsys.readouterr()
    out = json.loads(printed.out)
    assert not out["converged"] and out["iterations"] == 200
    assert printed.err.splitlines() == [f"contgrasp grasp: error: no optimal grasp: {out['message']}"]
    assert out["message"].startswith("iteration limit 200 reached")
