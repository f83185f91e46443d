"""The holding study (contgrasp_core.holding.study): rank correlations against known
relations, a tiny real study that resumes without recomputing, and its figure."""

from __future__ import annotations

import json
import math
import re
from typing import Any
from dataclasses import replace
from pathlib import Path

import numpy as np

import pytest

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.holding import GraspFailure, HoldExperiment, HoldSettings
from contgrasp_core.holding.study import (PREDICTORS, RESPONSES, StudySpec, _spearman_rows, correlations, expand_symmetric,
                                          load_results, base_si, pose_scenario, run_study, study_pose)
from contgrasp_core.rod.session import run_sampled
from contgrasp_core.scenario import PAPER


def _rows(n: int, relation) -> list[dict]:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(1)
    rows = []
    for i in range(n):
        q = float(rng.uniform(0.1, 2.0))
        row = {"key": f"grid:{i},0", "status": "ok", **{p: q for p in PREDICTORS}}
        row.update({r: relation(q, rng) for r in RESPONSES})
        rows.append(row)
    rows.append({"key": "grid:99,0", "status": "RunFailure: did not settle", "static_Q1": 5.0})
    return rows


def test_correlations_find_monotone_relations_and_none_in_noise() -> None:
    up = correlations(_rows(20, lambda q, rng: q**3 + 1.0), boot=300)
    assert up["static_Q1"]["capacity_min"]["rho"] == 1.0 and up["Q3"]["stiffness_min"]["low"] > 1.0 - 1e-12
    assert up["Q1"]["stiffness_det"]["n"] == 20  # (the failed pose is left out)
    down = correlations(_rows(20, lambda q, rng: -np.log(q)), boot=300)
    assert down["Q2"]["capacity_min"]["rho"] < -1.0 + 1e-12
    noise = correlations(_rows(40, lambda q, rng: float(rng.normal())), boot=500)
    c = noise["static_Q1"]["capacity_min"]
    assert c["low"] < 0 < c["high"] and abs(c["rho"]) < 0.5


def test_the_bootstrap_ranks_every_resample_as_scipy_does_one_at_a_time() -> None:
    """The bootstrap's resamples are ranked all at once; each must be scipy's Spearman rho of
    that resample (ties given average ranks), NaN where a side does not vary."""
    from scipy.stats import spearmanr

    rng = np.random.default_rng(3)
    pairs = np.column_stack([rng.integers(0, 5, 9).astype(float), rng.normal(size=9)])  # (ties in x)
    picks = pairs[rng.integers(0, 9, (400, 9))]
    picks[0, :, 0] = 2.0  # a resample whose x does not vary
    picks[1, :, 1] = picks[1, 0, 1]  # one whose y does not
    got = _spearman_rows(picks)
    assert np.isnan(got[0]) and np.isnan(got[1])
    want = [spearmanr(p[:, 0], p[:, 1]).statistic if np.ptp(p[:, 0]) > 0 and np.ptp(p[:, 1]) > 0 else np.nan for p in picks]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.isfinite(got[2:]).sum() > 350


def test_grasped_is_ranked_over_every_pose_and_symmetric_copies_do_not_count() -> None:
    """Whether a pose grasped at all is a response over every pose that ran (the failed ones
    too, not the code's errors); only the static map's measures exist there."""
    rows = [{"key": f"grid:{i},0", "status": "ok" if i >= 5 else "RunFailure: no", "outcome": "held" if i >= 5 else "no contact",
             "static_Q1": float(i), **({"Q1": float(i)} if i >= 5 else {})} for i in range(10)]
    rows.append({"key": "grid:10,0", "status": "RunFailure: bug", "outcome": "error", "static_Q1": 0.5})
    rows.append({**rows[0], "key": "grid:11,0", "same_as": "grid:0,0"})
    c = correlations(rows, boot=200)
    assert c["static_Q1"]["grasped"]["n"] == 10 and c["static_Q1"]["grasped"]["rho"] == pytest.approx(math.sqrt(25 / 33))  # (ranks 1..10 against two ties of 5)
    assert math.isnan(c["Q1"]["grasped"]["rho"])  # (every pose with a settled Q1 grasped)


def test_bound_min_is_the_weakest_measured_friction_bound() -> None:
    """The settled grasp's friction bound enters the correlations as its smallest value over
    the measured directions (the study's records keep it per direction); a record without it
    gives no value, and one missing direction none (not the minimum of the others)."""
    def row(i: int, bounds: list[float | None]) -> dict[str, Any]:
        return {"key": f"grid:{i},0", "status": "ok", "outcome": "held", "capacity_min": float(i),
                "capacity": [{"friction_bound": b} for b in bounds]}

    rows = [row(i, [3.0 * i, float(i), 2.0 * i + 7.0]) for i in range(1, 9)]
    assert correlations(rows, boot=50)["bound_min"]["capacity_min"]["rho"] == pytest.approx(1.0)
    rows = [row(i, [float(9 - i), 50.0]) for i in range(1, 9)]
    assert correlations(rows, boot=50)["bound_min"]["capacity_min"]["rho"] == pytest.approx(-1.0)
    rows += [row(20, [float("nan"), 0.001]), row(21, [None, 0.001]), {**row(22, []), "capacity": []}]
    assert correlations(rows, boot=50)["bound_min"]["capacity_min"]["n"] == 8


@pytest.mark.parametrize(("obj", "psi_steps", "rows"), [("circle", 24, 1), ("ellipse", 24, 12), ("ellipse", 5, 5),
                                                       ("ellipse:5,5", 24, 1), ("deformed:5,0.5,3,0", 24, 8),
                                                       ("deformed:5,0.5,5,0", 24, 24)])
def test_distinct_rows_follow_the_objects_rotations(obj: str, psi_steps: int, rows: int) -> None:
    assert StudySpec(object=obj, psi_steps=psi_steps).distinct_rows() == rows


def test_a_rotated_base_grasps_the_same_and_expand_symmetric_turns_the_pose() -> None:
    """The premise of measuring one row per symmetry class: a circle's grasp from a base turned
    by any angle about the centre settles at the same time in the turned shape."""
    spec = StudySpec(object="circle", psi_steps=4, d_steps=1, nodes=31)
    base, phi = (0.0, -10.0, 0.0), 0.7
    c, s = math.cos(phi), math.sin(phi)
    turned = (-s * base[1], c * base[1], phi)
    a, b = (run_sampled(pose_scenario(spec, p)) for p in (base, turned))
    assert a.settled and b.settled and a.settle_time == pytest.approx(b.settle_time, abs=0.01)
    centre = np.array(PAPER.object.center)
    xa, xb = a.observe().x - centre, b.observe().x - centre
    assert np.abs(xa @ np.array([[c, s], [-s, c]]) - xb).max() < 1e-6  # xa turned by phi
    k = np.arange(9.0).reshape(3, 3)
    row = {"key": "grid:0,0", "status": "ok", "base": [0.08, 0.03, 0.0], "stiffness": k.tolist(),
           "capacity": [{"direction": [1.0, 0.0, 0.0], "wrench": [0.03, 0.0, 0.0]}]}
    full = expand_symmetric(spec, [row])
    assert [r["key"] for r in full] == ["grid:0,0", "grid:1,0", "grid:2,0", "grid:3,0"]
    quarter = full[1]
    assert quarter["same_as"] == "grid:0,0" and np.allclose(quarter["base"], [0.13, 0.08, math.pi / 2])
    r = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert np.allclose(quarter["stiffness"], r @ k @ r.T) and np.allclose(quarter["capacity"][0]["wrench"], [0.0, 0.03, 0.0])


@pytest.mark.heavy
def test_an_arm_that_does_not_touch_the_object_is_a_no_contact_outcome() -> None:
    """Within reach (4.5 cm from the boundary, the arm 7.85 cm long) but pointing away from the
    object: a no-contact outcome. A base out of reach is refused before any run
    (:func:`contgrasp_core.scenario.check_start`)."""
    spec = StudySpec(object="circle", nodes=31)
    with pytest.raises(GraspFailure, match="no node touched the object for 0.2 s") as info:
        HoldExperiment(pose_scenario(spec, (0.0, -14.0, -math.pi / 2)), HoldSettings(contact_wait=0.2)).grasp()
    assert info.value.outcome == "no contact"
    with pytest.raises(InvalidParameterError, match="out of the arm's reach"):
        pose_scenario(spec, (0.0, -40.0, 0.0))
    # in a study such a pose is one result, outcome "refused", not the end of the study
    row = study_pose(spec, "grid:0,0", (0.0, -40.0, 0.0), (1.0, 2.0, 3.0))
    assert row["outcome"] == "refused" and "out of the arm's reach" in row["status"]
    assert row["base"] == pytest.approx(list(base_si(spec, (0.0, -40.0, 0.0))))


@pytest.mark.heavy
def test_a_tiny_study_runs_resumes_and_draws(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two base poses of the circle's map and the three optima, the rod scenario's arm (the map's
    thick uniform arm folds through itself under the paper's law: outcome "invalid"), a coarse rod
    and short ramps: every pose gets a result line; running again computes nothing and returns the
    same rows; a file of another specification is refused before the map is computed."""
    spec = StudySpec(object="circle", psi_steps=4, d_steps=2, nodes=51, arm="rod",
                     hold=HoldSettings(directions=1, ramp_time=0.4, hold_time=0.3, release_time=0.3, contact_wait=3.0))
    out = tmp_path / "study.jsonl"
    qm, rows = run_study(spec, out, executor="processes", workers=2)  # (the process pool in a real study)
    # (the circle's rows are its row 0 turned)
    assert sorted(r["key"] for r in rows) == ["grid:0,0", "grid:0,1", "optimum:Q1", "optimum:Q2", "optimum:Q3"]
    assert all(r["outcome"] in ("held", "no contact", "not settled", "not held", "invalid") for r in rows)
    assert all(r["versions"]["numpy"] == np.__version__ and set(r["versions"]) == {"numpy", "scipy", "numba"} for r in rows)
    # (from these grid bases the arm's 1 mm tip curls tighter than its radius within 20 ms, or strikes
    # the object 0.4 r deep: outcome "invalid"; the paper's own base gives a held grasp, measured here)
    held = study_pose(replace(spec, nodes=101), "grid:0,0", (-16.0, -16.0, 0.0), (1.0, 2.0, 3.0))
    for r in [held, *(r for r in rows if r["status"] == "ok")]:
        assert r["status"] == "ok" and r["outcome"] == "held"
        assert np.asarray(r["stiffness"]).shape == (3, 3) and len(r["capacity"]) == 3 and r["Q1"] > 0
        assert r["pressure_max"] > 0 and 0 < r["settle_time_s"] <= spec.duration  # (the settled grasp presses)
    lines = out.read_text().splitlines()
    # the static wrench capacity Q_H of each pose's optimal grasp (docs/holding.md (M3)) is in every row, written too
    from contgrasp_core.arm import BasePose
    from contgrasp_core.holding.measure import static_capacity

    assert all(json.loads(line)["static_QH"] >= 0.0 for line in lines[1:])
    assert all(math.isnan(json.loads(line)["cage_QH"]) for line in lines[1:])  # (the paper's law has no cage)
    grid = next(r for r in rows if r["key"] == "grid:0,0")
    assert grid["static_QH"] == static_capacity(spec.map_spec(), BasePose(*qm.base[0, 0]), spec.hold.mu).measure
    qm2, rows2 = run_study(spec, out, executor="serial")
    assert out.read_text().splitlines() == lines and rows2 == rows
    assert load_results(out)[0]["key"] == "spec"
    # a file that names the object as it was given (before the study named it by its one name,
    # "circle:5") resumes: the same object
    assert load_results(out)[0]["object"] == "circle:5" == spec.object
    older = tmp_path / "older.jsonl"
    older.write_text(out.read_text().replace('"object": "circle:5"', '"object": "circle"', 1))
    assert run_study(spec, older, executor="serial")[1] == rows and older.read_text().count("\n") == len(lines)
    # a row measured with another static map (here: its static Q1 altered) is reported with
    # today's map and marked, the others are not
    tampered = tmp_path / "tampered.jsonl"
    edited = [json.loads(line) for line in lines]
    for row in edited:
        if row["key"] == "grid:0,0":
            row["static_Q1"] *= 2.0
    tampered.write_text("".join(json.dumps(row) + "\n" for row in edited))
    marked = {r["key"]: r for r in run_study(spec, tampered, executor="serial")[1]}
    assert marked["grid:0,0"]["map_changed"] and marked["grid:0,0"]["static_Q1"] == grid["static_Q1"]
    assert not any(r.get("map_changed") for k, r in marked.items() if k != "grid:0,0")
    assert "map_changed" not in grid
    import contgrasp_core.holding.study as study

    def no_map(*args: object, **kwargs: object) -> None:
        raise AssertionError("the map was computed for a file that is refused")

    monkeypatch.setattr(study, "quality_map", no_map)
    with pytest.raises(InvalidParameterError, match=r"another specification \(it differs in duration, nodes\)"):
        run_study(replace(spec, nodes=41, duration=2.0), out, executor="serial")
    from contgrasp_core.figures.holding import study_figure

    fig = study_figure(qm, expand_symmetric(spec, rows))
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert any("static Q1" in t for t in titles) and any("capacity" in t for t in titles)


def test_a_second_writer_is_refused_until_the_first_is_gone(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Another process holding the study file's lock (a study writing it): run_study refuses at
    once with WriteError, before the map and without touching the file; once that process is
    killed (SIGKILL: no clean-up of its own) the lock is free and the study starts."""
    import subprocess
    import sys

    import contgrasp_core.holding.study as study
    from contgrasp_core.errors import WriteError

    out = tmp_path / "study.jsonl"
    out.write_text('{"key": "spec"}\n')
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from filelock import FileLock; "
                               f"lock = FileLock({str(out) + '.lock'!r}); lock.acquire(); print('locked', flush=True); time.sleep(120)"],
                              stdout=subprocess.PIPE, text=True)
    started: list[bool] = []

    def map_started(*args: object, **kwargs: object) -> None:
        started.append(True)
        raise KeyboardInterrupt  # (stops the study once it is past the lock)

    monkeypatch.setattr(study, "quality_map", map_started)
    spec = StudySpec(object="ellipse", psi_steps=4, d_steps=1, nodes=31)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        with pytest.raises(WriteError, match=r"another holding study is writing to .*study\.jsonl"):
            run_study(spec, out, executor="serial")
        assert not started and out.read_text() == '{"key": "spec"}\n'
    finally:
        holder.kill()
        holder.wait()
    out.unlink()
    with pytest.raises(KeyboardInterrupt):
        run_study(spec, out, executor="serial")
    assert started == [True]


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


@pytest.mark.heavy
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="reads the process tree from /proc (Linux)")
def test_ctrl_c_stops_a_study_with_two_workers_at_once(tmp_path: Path) -> None:
    """SIGINT to the study's process group (a terminal's Ctrl-C) while two workers compute:
    the command ends within 10 s with one line and exit code 130, and no process of it is left
    (it once printed two tracebacks and hung in the pool's shutdown for minutes)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    cmd = [sys.executable, "-m", "contgrasp_core.cli", "holding-study", "--object", "ellipse", "--psi-steps", "8",
           "--d-steps", "2", "--nodes", "31", "--executor", "processes", "--workers", "2", "--out", str(tmp_path / "s.jsonl")]
    # (the child inherits a handled SIGINT: tests/conftest.py sees to it)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env=dict(os.environ, MPLBACKEND="Agg"))
    try:
        end = time.monotonic() + 120
        while len(_children(proc.pid)) < 2 and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.1)
        workers = _children(proc.pid)
        assert len(workers) >= 2 and proc.poll() is None, (workers, proc.poll())
        time.sleep(1.0)  # inside the tasks
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        # (0.3-0.6 s here with a CI run beside it; it once took over 30 s: the main thread slept in
        # poll() while the kernel handed the SIGINT to another thread, contgrasp_core.executors)
        _, err = proc.communicate(timeout=10)
        assert time.monotonic() - t0 < 10
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err[-2000:]
    lines = [line for line in err.splitlines() if line.strip() and "%|" not in line and "\r" not in line]
    assert lines == ["contgrasp holding-study: interrupted"], err[-2000:]
    time.sleep(0.5)
    assert not [w for w in workers if Path(f"/proc/{w}").exists() and "zombie" not in Path(f"/proc/{w}/status").read_text()]


def test_the_study_takes_the_holding_law_a_free_release_and_a_longer_arm(capsys: pytest.CaptureFixture[str]) -> None:
    """``--law reactive --support 0 --length-fraction F``: the map's arm and the rod's are F
    perimeters long, every pose's scenario runs the holding law, the spec records the options
    (and leaves them out at their defaults, so a file recorded before they existed resumes)."""
    from contgrasp_core.cli import main
    from contgrasp_core.holding.study import _spec_dict

    spec = StudySpec(object="circle", law="reactive", length_fraction=1.0, hold=HoldSettings(support=0.0))
    assert spec.map_spec().length_fraction == 1.0
    scenario = pose_scenario(spec, (0.0, -8.0, 0.0))
    assert scenario.law == "reactive" and scenario.rod.length == pytest.approx(2 * np.pi * 0.025)
    assert _spec_dict(spec)["law"] == "reactive" and _spec_dict(spec)["hold"]["support"] == 0.0
    assert "law" not in _spec_dict(StudySpec()) and "length_fraction" not in _spec_dict(StudySpec())
    with pytest.raises(InvalidParameterError, match="unknown law 'grip'"):
        StudySpec(law="grip")
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(["holding-study", "--law", "grip", "--out", "x.jsonl"])
    assert exit_info.value.code == 2
    assert "invalid choice: 'grip'" in capsys.readouterr().err


def test_the_study_takes_the_depth_regulation_of_the_holding_law(capsys: pytest.CaptureFixture[str]) -> None:
    """``--depth-gain K`` (docs/holding.md (H7)): every pose's scenario runs the holding law with
    that gain (and the law's other defaults), the spec records it only when set (older files
    resume), and a gain without the holding law, negative or not finite is refused."""
    from contgrasp_core.cli import main
    from contgrasp_core.control.hold_law import HoldLawSettings
    from contgrasp_core.holding.study import _spec_dict

    spec = StudySpec(object="circle", law="reactive", arm="rod", depth_gain=10.0)
    assert pose_scenario(spec, (0.0, -8.0, 0.0)).hold_law == HoldLawSettings(depth_gain=10.0)
    assert _spec_dict(spec)["depth_gain"] == 10.0 and "depth_gain" not in _spec_dict(StudySpec(law="reactive"))
    assert pose_scenario(StudySpec(law="reactive"), (0.0, -8.0, 0.0)).hold_law == HoldLawSettings()
    with pytest.raises(InvalidParameterError, match="needs law hold or reactive"):
        StudySpec(depth_gain=10.0)
    for bad in (-1.0, float("nan")):
        with pytest.raises(InvalidParameterError, match="hold law depth_gain"):
            StudySpec(law="reactive", depth_gain=bad)
    capsys.readouterr()
    assert main(["holding-study", "--depth-gain", "5", "--out", "x.jsonl"]) == 2
    assert "needs law hold or reactive" in capsys.readouterr().err


def test_the_study_takes_the_dwell_and_measures_the_cage_before_simulating(capsys: pytest.CaptureFixture[str]) -> None:
    """``--dwell T`` (docs/holding.md (H8)) reaches every pose's law and the spec (only when
    set); without the holding law it is refused. Before simulating, every task of a holding-law
    study gets ``cage_QH`` (M4) of its pose's scenario (a base 3 units from the circle, heading
    along it: the cage wraps it, positive); the paper's law has none (NaN)."""
    from contgrasp_core.cli import main
    from contgrasp_core.control.hold_law import HoldLawSettings
    from contgrasp_core.holding.measure import cage_capacity
    from contgrasp_core.holding.study import _before_simulating, _spec_dict

    spec = StudySpec(object="circle", law="reactive", arm="rod", depth_gain=10.0, dwell=1.0)
    assert pose_scenario(spec, (0.0, -8.0, 0.0)).hold_law == HoldLawSettings(depth_gain=10.0, dwell=1.0)
    assert _spec_dict(spec)["dwell"] == 1.0 and "dwell" not in _spec_dict(StudySpec(law="reactive"))
    with pytest.raises(InvalidParameterError, match="needs law hold or reactive"):
        StudySpec(dwell=1.0)
    with pytest.raises(InvalidParameterError, match="hold law dwell"):
        StudySpec(law="reactive", dwell=-1.0)
    capsys.readouterr()
    assert main(["holding-study", "--dwell", "1", "--out", "x.jsonl"]) == 2
    assert "needs law hold or reactive" in capsys.readouterr().err
    tasks = [("grid:0,0", (0.0, -8.0, 0.0), (1.0, 1.0, 1.0))]
    spec = StudySpec(object="circle", law="reactive", arm="rod", d_steps=2)
    before = _before_simulating(spec, tasks)
    assert before["grid:0,0"]["cage_QH"] == cage_capacity(pose_scenario(spec, tasks[0][1]), spec.hold.mu).measure > 0
    paper = _before_simulating(replace(spec, law="paper"), tasks)
    assert math.isnan(paper["grid:0,0"]["cage_QH"]) and paper["grid:0,0"]["static_QH"] == before["grid:0,0"]["static_QH"]


def test_the_rod_arm_is_the_rod_scenarios_for_the_map_and_the_rod() -> None:
    """``arm="rod"``: the map's inner problem and every pose's rod are the rod scenario's tapered
    arm (length and radii in the paper's units through ``scale``, rho_d = r(s)); a length
    fraction with it is refused (it sets the map's arm only), and the spec leaves ``arm`` out at
    its default so older result files resume."""
    from contgrasp_core.holding.study import _spec_dict

    spec = StudySpec(object="ellipse", arm="rod", law="reactive")
    ms = spec.map_spec()
    perimeter = ms.boundary().length
    assert ms.length_fraction * perimeter * spec.scale == pytest.approx(PAPER.rod.length)
    assert ms.arm_radius_tip is not None
    assert (ms.arm_radius * spec.scale, ms.arm_radius_tip * spec.scale) == pytest.approx(
        (PAPER.rod.radius_base, PAPER.rod.radius_tip))
    assert ms.rho_d is None
    rod = pose_scenario(spec, (0.0, -12.0, 0.0)).rod
    assert (rod.length, rod.radius_base, rod.radius_tip) == (PAPER.rod.length, PAPER.rod.radius_base, PAPER.rod.radius_tip)
    assert rod.base_position == pytest.approx(base_si(spec, (0.0, -12.0, 0.0))[:2])
    assert _spec_dict(spec)["arm"] == "rod" and "arm" not in _spec_dict(StudySpec())
    with pytest.raises(InvalidParameterError, match="the length fraction sets the map's arm only"):
        StudySpec(arm="rod", length_fraction=1.0)
    with pytest.raises(InvalidParameterError, match="unknown arm 'claw'"):
        StudySpec(arm="claw")


def test_the_study_takes_an_outline_scaled_about_its_origin() -> None:
    """An outline in the paper's units (the kidney of tests/data) is scaled by ``scale`` about
    its own origin onto the rod scenario's object centre, and every polar angle is its own row
    (no symmetry assumed)."""
    path = Path(__file__).parent / "data" / "kidney_outline.csv"
    spec = StudySpec(object=f"outline:{path}", psi_steps=8, arm="rod")
    pts = np.loadtxt(path, delimiter=",", skiprows=2)
    rod_obj = spec.rod_object()
    assert np.asarray(rod_obj.points) == pytest.approx(spec.scale * pts + np.asarray(PAPER.object.center))
    assert rod_obj.boundary().length == pytest.approx(spec.scale * spec.object_spec().boundary().length, rel=1e-9)
    assert spec.distinct_rows() == 8
    with pytest.raises(InvalidParameterError, match="must be text"):
        StudySpec(object=3)  # type: ignore[arg-type]


@pytest.mark.parametrize(("line", "why"), [
    ('{"key": "grid:0,0", "base": [0.1, 0.2]}', "its 'base' is not three finite numbers"),
    ('{"key": "grid:0,0"}', "its 'base' is not three finite numbers"),
    ('{"key": "grid:0,0", "base": [0.1, "x", 0.0]}', "its 'base' is not three finite numbers"),
    ('{"base": [0.1, 0.2, 0.0]}', "an object with a text 'key'"),
    ('[1, 2, 3]', "an object with a text 'key'"),
    ('{"key": "grid:0,0", "base": [0.1, 0.2', "not a study result line"),
])
def test_a_malformed_results_line_is_refused_with_its_line_number(tmp_path: Path, line: str, why: str) -> None:
    out = tmp_path / "study.jsonl"
    out.write_text('{"key": "spec"}\n' + line + "\n")
    with pytest.raises(InvalidParameterError, match=rf"study.jsonl:2: .*{re.escape(why)}"):
        load_results(out)


@pytest.mark.heavy
def test_a_dask_study_computes_its_quality_map_on_the_cluster(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``holding-study --executor dask``: the quality map's columns go to the cluster too (they were
    computed serially on the client), the same map as a serial run's; the poses follow (left out here)."""
    distributed = pytest.importorskip("distributed")
    import contgrasp_core.holding.study as study

    maps: list[tuple[str, Any]] = []
    real = study.quality_map

    def spy(spec: Any, **kw: Any) -> Any:
        qm = real(spec, **kw)
        maps.append((kw["executor"], kw.get("scheduler"), qm))
        return qm

    monkeypatch.setattr(study, "quality_map", spy)
    monkeypatch.setattr(study, "run_tasks", lambda *a, **k: iter(()))
    spec = StudySpec(object="circle", psi_steps=4, d_steps=2, nodes=51, arm="rod")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            run_study(spec, tmp_path / "dask.jsonl", executor="dask", scheduler=cluster.scheduler_address)
            ran = client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.task_prefixes))  # (kinds of task it ran)
    assert [(m[0], m[1]) for m in maps] == [("dask", cluster.scheduler_address)] and ran > 0
    run_study(spec, tmp_path / "serial.jsonl", executor="serial")
    np.testing.assert_array_equal(maps[1][2].Q, maps[0][2].Q)
    np.testing.assert_array_equal(maps[1][2].valid, maps[0][2].valid)


def test_a_reactive_study_recorded_as_law_hold_is_refused_under_the_planned_hold(tmp_path: Path) -> None:
    """The reactive law was once named ``hold``: a file it wrote says ``"law": "hold"``. Under
    today's ``hold`` (the planned hold) the study records the playback's settings, so that file
    differs in them and is refused before anything is computed, never resumed as if planned;
    and today's reactive study refuses it too (its law differs)."""
    from contgrasp_core.holding.study import _spec_dict

    reactive = StudySpec(object="circle", law="reactive", arm="rod", nodes=11)
    planned = replace(reactive, law="hold")
    assert set(_spec_dict(planned)) - set(_spec_dict(reactive)) == {"playback"}
    assert _spec_dict(planned)["playback"] == {"plan_gain": 100.0, "plan_damping": 500.0, "plan_damping_time": 0.05,
                                               "plan_squeeze": 0.1, "plan_squeeze_time": 0.3}
    old = tmp_path / "old.jsonl"
    old.write_text(json.dumps({"key": "spec", **{**_spec_dict(reactive), "law": "hold"}}) + "\n")
    with pytest.raises(InvalidParameterError, match=r"another specification \(it differs in playback\)"):
        run_study(planned, old, executor="serial")
    with pytest.raises(InvalidParameterError, match=r"another specification \(it differs in law\)"):
        run_study(reactive, old, executor="serial")
