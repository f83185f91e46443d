"""A user's outline may start anywhere and run either way round: the seam s_o = 0 sits at its
first point (after orienting it counter-clockwise), and every comparison of arclengths is taken
modulo the perimeter L_o. Rotating the CSV rows moves the seam; reversing them flips
the orientation the file gives (the curve is re-oriented). Neither may change what is computed
about the same physical arm, and an arm across the seam must not look one perimeter off."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.cli import main
from contgrasp_core.objects import ObjectSpec

pytestmark = pytest.mark.heavy  # (about 16 s together: each test runs on one interpreter in CI)

KIDNEY = Path(__file__).parent / "data" / "kidney_outline.csv"
ROWS = np.loadtxt(KIDNEY, delimiter=",", comments="#", skiprows=2)
ROWS = ROWS[:-1] if np.array_equal(ROWS[0], ROWS[-1]) else ROWS  # the file closes itself: keep one copy
VARIANTS = [(k, rev) for k in (0, 1, 7, len(ROWS) // 2, len(ROWS) - 1) for rev in (False, True)]


def _variant(tmp_path: Path, shift: int, reverse: bool) -> Path:
    rows = np.roll(ROWS, -shift, axis=0)
    rows = rows[::-1] if reverse else rows
    if shift % 2:  # odd shifts also close the polygon explicitly, repeating the new first row
        rows = np.vstack([rows, rows[:1]])
    path = tmp_path / f"kidney_{shift}_{'cw' if reverse else 'ccw'}.csv"
    np.savetxt(path, rows, delimiter=",", header="x, y", comments="")
    return path


def _json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:  # type: ignore[type-arg]
    assert main([*args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)  # type: ignore[no-any-return]


def test_the_rotations_move_the_seam_to_many_places() -> None:
    assert len(ROWS) >= 20
    starts = {tuple(np.roll(ROWS, -k, axis=0)[0]) for k, _ in VARIANTS}
    assert len(starts) == 5


@pytest.mark.parametrize("shift,reverse", VARIANTS)
@pytest.mark.parametrize("s_o0_fraction", [0.0, 0.9])  # 0.9 L_o: the arm (L_o / 2 long) runs over the seam
def test_kinematics_across_the_seam(tmp_path: Path, capsys: pytest.CaptureFixture[str], shift: int, reverse: bool,
                                    s_o0_fraction: float) -> None:
    path = _variant(tmp_path, shift, reverse)
    length = ObjectSpec.from_outline(str(path)).boundary().length
    out = _json(capsys, "kinematics", "--outline", str(path), "--rho0", "0.5", "--alpha0", "1.5708",
                "--s-o0", f"{s_o0_fraction * length:.12g}")
    assert out["max_discrepancy"] < 1e-6, out["discrepancy"]  # never ~ one perimeter
    assert out["discrepancy"]["s_o"] < 1e-6 * length
    if s_o0_fraction:  # the shadow point did pass the seam: s_o (unwrapped) goes beyond L_o
        assert max(out["s_o"]) > length


def _same_point_s_o0(path: Path, s_o0: float) -> float:
    """The arclength, on the outline in ``path``, of the point at ``s_o0`` on the original file's curve."""
    point = ObjectSpec.from_outline(str(KIDNEY)).boundary().point(s_o0)
    return float(ObjectSpec.from_outline(str(path)).boundary().project(point[None, :]).s_o[0])


@pytest.mark.parametrize("shift,reverse", [(0, False), (7, False), (7, True), (len(ROWS) - 1, True)])
def test_grasp_does_not_depend_on_where_the_outline_starts(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          shift: int, reverse: bool) -> None:
    """The optimal grasp from one physical contact point is the same whatever row the file
    starts with and whichever way it runs (s_o0 given on each file's own arclength)."""
    length = ObjectSpec.from_outline(str(KIDNEY)).boundary().length
    s_o0 = 0.8 * length  # the grasp (arm 2 L_o / 3) wraps over the original file's seam
    ref = _json(capsys, "grasp", "--outline", str(KIDNEY), "--nodes", "120", "--rho0", "0.5", "--s-o0", f"{s_o0:.15g}")
    path = _variant(tmp_path, shift, reverse)
    moved = _same_point_s_o0(path, s_o0)
    out = _json(capsys, "grasp", "--outline", str(path), "--nodes", "120", "--rho0", "0.5", "--s-o0", f"{moved:.15g}")
    assert ref["converged"] and out["converged"] and out["constraints_ok"]
    assert out["cost"] == pytest.approx(ref["cost"], rel=1e-5)
    # the same arm in the plane (the curve is the same spline up to rounding)
    np.testing.assert_allclose(out["rho"], ref["rho"], atol=1e-5)
    np.testing.assert_allclose(out["alpha"], ref["alpha"], atol=1e-5)
    # the shadow points agree modulo the perimeter, after the shift of the seam
    ds = np.asarray(out["s_o"]) - moved - (np.asarray(ref["s_o"]) - s_o0)
    assert np.max(np.abs(ds)) < 1e-4 * length


@pytest.mark.parametrize("shift,reverse", [(7, False), (13, True)])
def test_grasp_text_from_a_rotated_outline(tmp_path: Path, capsys: pytest.CaptureFixture[str], shift: int,
                                           reverse: bool) -> None:
    path = _variant(tmp_path, shift, reverse)
    assert main(["grasp", "--outline", str(path), "--nodes", "120", "--rho0", "0.5", "--s-o0", "30"]) == 0
    text = capsys.readouterr().out
    assert "converged: True" in text
