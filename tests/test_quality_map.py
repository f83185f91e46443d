"""Quality maps over the base region D: geometry of D, symmetries, executors, invalid poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.objects import paper_object
from contgrasp_core.quality_map import MapSpec, disc_pose, load_map, maximise, quality_map, save_map

FAST = dict(nodes=80, solver_tol=1e-9)


@pytest.mark.parametrize("name", ["circle", "ellipse", "deformed"])
def test_disc_pose_is_at_distance_d_on_the_ray(name: str) -> None:
    b = paper_object(name)
    for psi, d in [(0.0, 3.0), (1.1, 7.5), (4.0, 13.0)]:
        pose = disc_pose(b, psi, d)
        assert np.arctan2(pose.y, pose.x) % (2 * np.pi) == pytest.approx(psi % (2 * np.pi), abs=1e-12)
        assert b.project(np.array([[pose.x, pose.y]])).signed_distance[0] == pytest.approx(d, abs=1e-9)
        assert pose.theta == pytest.approx(psi + np.pi / 2)
    assert np.hypot(*[disc_pose(paper_object("circle"), 0.7, 4.0).x, disc_pose(paper_object("circle"), 0.7, 4.0).y]) == pytest.approx(9.0)


def test_circle_map_is_radially_symmetric() -> None:
    qm = quality_map(MapSpec("circle", psi_steps=5, d_steps=2, **FAST), executor="serial", optimise=False)
    assert qm.valid.all()
    for k in range(3):
        np.testing.assert_allclose(qm.Q[k], np.broadcast_to(qm.Q[k][0], qm.Q[k].shape), rtol=1e-6)
    # higher quality closer to the object
    assert np.all(qm.Q[0][:, 0] > qm.Q[0][:, 1])


def test_ellipse_map_has_the_point_symmetry_but_not_the_reflections() -> None:
    """Rotating by pi maps the problem onto itself (the arm still wraps counter-clockwise);
    reflecting about an axis reverses the wrapping direction, so it is not a symmetry."""
    qm = quality_map(MapSpec("ellipse", psi_steps=8, d_steps=1, d_min=3.0, d_max=3.0, **FAST), executor="serial", optimise=False)
    assert qm.valid.all()
    Q = qm.Q[:, :, 0]
    np.testing.assert_allclose(Q[:, 4:], Q[:, :4], rtol=1e-6)  # psi + pi
    mirror = Q[:, (-np.arange(8)) % 8]  # psi -> -psi (reflection about the major axis)
    assert np.max(np.abs(mirror - Q) / np.abs(Q)) > 1e-2


def test_deformed_circle_map_has_threefold_symmetry_and_invalid_poses_are_marked() -> None:
    spec = MapSpec("deformed", psi_steps=6, d_steps=2, d_min=3.0, d_max=13.0, **FAST)
    qm = quality_map(spec, executor="serial", optimise=False)
    assert qm.valid[:, 0].all()
    Q = qm.Q[:, :, 0]
    np.testing.assert_allclose(Q[:, 2:4], Q[:, 0:2], rtol=1e-6)  # psi + 2 pi / 3
    np.testing.assert_allclose(Q[:, 4:6], Q[:, 0:2], rtol=1e-6)
    # 13 away from a concave part (concave radius ~7.2) the shadow point cannot move forward:
    # such poses are invalid, with the reason, and carry no number
    # (on a bay's symmetry axis the two flanks are equally close, so which shadow point the
    # projection picks - and whether the pose is feasible - is a tie broken by rounding)
    concave = np.isclose(np.mod(qm.psi - np.pi / 3, 2 * np.pi / 3), 0.0)
    invalid = ~qm.valid[:, 1]
    assert invalid.any() and not np.any(invalid & ~concave)
    assert np.all(np.isnan(qm.Q[:, invalid, 1]))
    for i in np.flatnonzero(invalid):
        assert qm.reasons[i][1].startswith("inner solve failed") and "singular" in qm.reasons[i][1]
    assert all(r == "ok" for i in np.flatnonzero(~concave) for r in qm.reasons[i])


@pytest.mark.heavy
def test_executors_give_identical_maps() -> None:
    distributed = pytest.importorskip("distributed")
    spec = MapSpec("ellipse", psi_steps=4, d_steps=2, **FAST)
    serial = quality_map(spec, executor="serial", optimise=False)
    procs = quality_map(spec, executor="processes", workers=2, optimise=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        dask = quality_map(spec, executor="dask", scheduler=cluster.scheduler_address, optimise=False)
    for other in (procs, dask):
        np.testing.assert_array_equal(other.valid, serial.valid)
        np.testing.assert_array_equal(other.Q, serial.Q)


@pytest.mark.heavy
def test_nelder_mead_improves_on_the_grid_within_bounds(tmp_path) -> None:  # type: ignore[no-untyped-def]
    spec = MapSpec("ellipse", psi_steps=6, d_steps=2, **FAST)
    qm = quality_map(spec, executor="serial", optimise=True)
    for opt in qm.optimum.values():
        assert spec.d_min <= opt["d"] <= spec.d_max
        assert opt["value"] >= opt["grid_value"] * (1 - 1e-12)
        assert len(opt["x"]) == len(opt["y"]) == spec.nodes
        # the optimal arm starts at the optimal base
        assert (opt["x"][0], opt["y"][0]) == pytest.approx((opt["base"]["x"], opt["base"]["y"]), abs=1e-9)
    back = load_map(save_map(qm, tmp_path / "map"))
    np.testing.assert_array_equal(back.Q, qm.Q)
    np.testing.assert_array_equal(back.valid, qm.valid)
    assert back.optimum == qm.optimum and back.spec == spec
    with pytest.raises(InvalidParameterError):
        maximise(qm, "Q4")


def test_bad_specs_rejected(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InvalidParameterError):
        MapSpec("square")
    with pytest.raises(InvalidParameterError):
        MapSpec("circle", d_min=5.0, d_max=3.0)
    with pytest.raises(InvalidParameterError):
        MapSpec("circle", contact_tol=-0.1)
    with pytest.raises(InvalidParameterError):
        quality_map(MapSpec("circle", psi_steps=1, d_steps=1, **FAST), executor="dask")
    with pytest.raises(InvalidParameterError):
        load_map(tmp_path / "missing")


def test_a_tapered_map_arm_tracks_its_own_radius() -> None:
    """``arm_radius_tip`` tapers the inner problem's arm linearly (Sec. III-A's arm) and
    ``rho_d = None`` makes the target its radius r(s); a bad tip radius is refused."""
    from contgrasp_core.quality_map import optimal_grasp

    spec = MapSpec("circle", psi_steps=1, d_steps=1, arm_radius=2.0, arm_radius_tip=0.2, rho_d=None,
                   length_fraction=1.2, nodes=41)
    problem, res = optimal_grasp(spec, spec.boundary(), disc_pose(spec.boundary(), 0.0, 5.0))
    s = problem.s
    length = 1.2 * 2 * np.pi * 5.0
    assert problem.arm.radius(s) == pytest.approx(2.0 + (0.2 - 2.0) * s / length)
    assert problem.disc.rho_d == pytest.approx(2.0 + (0.2 - 2.0) * s / length)
    assert res.converged
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InvalidParameterError, match="arm_radius_tip"):
            MapSpec("circle", arm_radius_tip=bad)


def _egg(path: Path, shift: float = 20.0) -> str:
    """An egg r = 5 + 0.8 cos t moved ``shift`` in x (by 20: the origin (0, 0) lies outside it)."""
    t = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    r = 5.0 + 0.8 * np.cos(t)
    np.savetxt(path, np.column_stack([shift + r * np.cos(t), r * np.sin(t)]), delimiter=", ", header="x, y", comments="")
    return str(path)


def test_an_object_not_around_the_origin_is_refused_before_any_solve(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Bases lie on rays from the origin: an object away from it has no pose at all, so the
    spec (and the command, exit 2 in one line) refuses it instead of computing an empty map."""
    from contgrasp_core.cli import main
    from contgrasp_core.objects import FIG2_SCALE, ObjectSpec

    outline = _egg(tmp_path / "egg_shift.csv")
    with pytest.raises(InvalidParameterError, match=r"origin must lie inside .* whose centre is at \(20\.\d+, 0\)"):
        MapSpec(ObjectSpec.from_cli(None, outline, FIG2_SCALE))
    assert main(["quality-map", "--outline", outline, "--psi-steps", "8", "--d-steps", "3", "--executor", "serial"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and "shift the object so that it surrounds the origin" in err
    assert "quality map" not in err  # (no progress bar: nothing was computed)


def test_n_solves_counts_the_poses_actually_solved() -> None:
    """A pose without a base pose or with an invalid initial state is not solved; a failed
    or unconverged solve is."""
    from dataclasses import replace

    qm = quality_map(MapSpec("circle", psi_steps=1, d_steps=2, nodes=40), executor="serial", optimise=False)
    assert qm.n_solves == 2
    for reasons, solves in ((["no base pose: x", "invalid initial state: y"], 0), (["inner solve failed: z", "not converged"], 2),
                            (["ok", "no base pose: x"], 1)):
        assert replace(qm, reasons=[reasons]).n_solves == solves


def test_out_keeps_a_suffix_it_does_not_write(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--out FILE``: FILE, FILE.npz and FILE.json name the same pair; any other suffix is part
    of the name (it was replaced: ``--out egg.csv`` overwrote an unrelated ``egg.json``)."""
    from contgrasp_core.cli import main

    (tmp_path / "egg.json").write_text("unrelated")
    out = str(tmp_path / "egg.csv")
    assert main(["quality-map", "--psi-steps", "1", "--d-steps", "1", "--nodes", "40", "--executor", "serial",
                 "--no-optimise", "--out", out]) == 0
    assert f"saved: {out}.npz and {out}.json" in capsys.readouterr().out
    assert (tmp_path / "egg.json").read_text() == "unrelated" and not (tmp_path / "egg.npz").exists()
    assert load_map(out).n_solves == load_map(out + ".npz").n_solves == 1

    from contgrasp_core.quality_map import map_paths

    for name, npz in (("m", "m.npz"), ("m.npz", "m.npz"), ("m.json", "m.npz"), ("m.v2", "m.v2.npz"), ("m_r0.5", "m_r0.5.npz")):
        assert map_paths(tmp_path / name) == (tmp_path / npz, tmp_path / (npz[:-4] + ".json"))
    with pytest.raises(InvalidParameterError, match="needs a file name"):
        map_paths("")


def test_load_refuses_the_options_of_a_new_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--load`` shows the saved map as it was computed: an object, a grid, an executor or
    ``--out`` given with it would be ignored (the loaded map was printed instead), so each is refused."""
    from contgrasp_core.cli import main

    saved = str(tmp_path / "map")
    assert main(["quality-map", "--psi-steps", "1", "--d-steps", "1", "--nodes", "40", "--executor", "serial",
                 "--no-optimise", "--out", saved, "--json"]) == 0
    for extra in (["--outline", _egg(tmp_path / "egg.csv")], ["--object", "ellipse"], ["--psi-steps", "3"],
                  ["--d-max", "9"], ["--executor", "serial"], ["--no-optimise"], ["--out", str(tmp_path / "again")]):
        capsys.readouterr()
        assert main(["quality-map", "--load", saved, *extra]) == 2, extra
        out, err = capsys.readouterr()
        assert out == "" and err.splitlines() == [
            f"contgrasp quality-map: error: {extra[0]} does nothing with --load (a saved map is shown as it was computed): "
            "it needs a map computed anew (no --load)"]
    assert main(["quality-map", "--load", saved, "--metric", "Q1", "--psi-steps", "24"]) == 0  # (the defaults pass)
    assert not (tmp_path / "again.npz").exists()


def test_the_optimal_base_heading_is_given_in_0_to_2_pi(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """theta0 = psi + pi/2 with psi in [0, 2 pi) was reported unwrapped (6.32 rad); now in
    [0, 2 pi) as psi, the same in the JSON and the text."""
    import json

    from contgrasp_core.cli import main

    argv = ["quality-map", "--outline", _egg(tmp_path / "egg.csv", shift=0.0), "--psi-steps", "8", "--d-steps", "2",
            "--nodes", "40", "--executor", "serial", "--metric", "Q2"]
    assert main([*argv, "--json"]) == 0
    opt = json.loads(capsys.readouterr().out)["optimum"]["Q2"]
    assert opt["psi"] > 1.5 * np.pi  # (the egg's Q2 optimum: psi + pi/2 passes 2 pi)
    assert opt["base"]["theta"] == pytest.approx(opt["psi"] - 1.5 * np.pi, abs=1e-12)
    assert main(argv) == 0
    assert f"heading {opt['base']['theta']:.4g} rad" in capsys.readouterr().out
