"""``contgrasp analyze``: a recorded run analysed offline reproduces the launcher's summary and,
recomputed from the rod states with the nodes' own functions, the recorded contact and quality."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from collections.abc import Iterable, Iterator
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from conftest import fresh_domain_id

from contgrasp_core.cli import main
from contgrasp_core.scenario import PAPER
from contgrasp_ros.recordings import cli_analyze
from contgrasp_ros.recordings.analysis import MixedRecordingError, analyze, check
from contgrasp_ros.recordings.recompute import recompute
from contgrasp_ros.recordings.run_data import load_run
from contgrasp_ros.bag.reader import iter_decoded, iter_raw, open_recording
from contgrasp_ros.bag.writer import BagWriter
from contgrasp_ros.launcher.summary import ContactStats, FinalQuality, FinalState, RunSummary, build_summary, contact_stats

pytestmark = pytest.mark.heavy(per_module=True)  # (its tests share one recorded graph run: one shard makes it)

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[1]
ROD, CONTACT, COUPLE, QUALITY = "/contgrasp/rod_state", "/contgrasp/contact", "/contgrasp/couple", "/contgrasp/quality"


def cli(*argv: str) -> int:
    return main(["analyze", *argv], extra=[cli_analyze.add_parser])


def copy_recording(rec: Any, dst: Path, rows: Iterable[tuple[str, Any, bytes, int, int]],
                   dropped_records: tuple[str, ...] = ()) -> None:
    """Write ``rows`` of ``rec`` (topic, raw message, its data, log time, publish time: each
    possibly changed) as a new recording ``dst`` with ``rec``'s metadata records but ``dropped_records``."""
    out = BagWriter(dst)
    for topic, m, data, log_ns, publish_ns in rows:
        out.add_topic(topic, m.type, m.channel.metadata.get("offered_qos_profiles", ""),
                      m.channel.metadata.get("topic_type_hash", ""), definition=m.schema.data.decode())
        out.write(topic, data, log_ns, publish_ns, m.sequence)
    out.records.update({k: v for k, v in rec.metadata_records().items() if k not in ("rosbag2", *dropped_records)})
    out.close()


def as_is(m: Any) -> tuple[str, Any, bytes, int, int]:
    """A raw message as :func:`copy_recording` writes it unchanged."""
    return m.topic, m, m.data, m.log_time_ns, m.publish_time_ns


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """One short real run of the graph (separate processes), recorded, with the launcher's summary.

    The scenario is the packaged one with a looser settle rule so the arm is judged settled
    after ~0.4 s of sim time (~220 lock-step steps). The duration is set in the parameter file:
    ``--duration`` does not reach a separate-process simulator whose section of the file sets it.
    """
    pytest.importorskip("rclpy")
    from contgrasp_ros.launcher.cli import default_params_file

    d = tmp_path_factory.mktemp("analysis")
    data = yaml.safe_load(default_params_file().read_text())
    data["rod_simulator"]["ros__parameters"].update(duration=0.6, settle_speed=0.05, settle_hold=0.04, min_time=0.2)
    params = d / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    bag, summary_file = d / "run", d / "summary.json"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    proc = subprocess.run(
        [str(BIN / "contgrasp-launch"), "--domain-id", str(fresh_domain_id()), "--params", str(params),
         "--bag", str(bag), "--summary-file", str(summary_file), "--json"],
        capture_output=True, text=True, timeout=300, env=env,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(summary_file.read_text())
    assert summary["settled"] and summary["steps"] > 100
    return bag, summary


def test_analyze_reproduces_the_launcher_summary(recording: tuple[Path, dict]) -> None:
    bag, summary = recording
    r = analyze(bag)
    for key in ("object", "settled", "settle_time_s", "sim_time_s", "steps", "missed_deadlines", "max_penetration",
                "mean_abs_rho_ratio_minus_1_contact", "mean_abs_alpha_minus_half_pi_contact"):
        assert r[key] == summary[key], key
    for key in ("s", "x", "y", "theta"):
        np.testing.assert_allclose(r["final"][key], summary["final"][key], rtol=0, atol=1e-12)
    fq, sq = r["final_quality"], summary["final_quality"]
    assert fq["valid"] == sq["valid"] is True
    for key in ("Q1", "Q2", "Q3", "contact_length"):
        np.testing.assert_allclose(fq[key], sq[key], rtol=1e-12, atol=0)
    # the settle rule replayed on the complete rod states gives the simulator's answer
    assert r["step_gaps"]["contiguous"] and r["step_gaps"]["first_step"] == 0
    assert r["settled_recomputed"] is True  # (at the stamps, simulated time rounded to ns)
    assert r["settle_time_recomputed_s"] == pytest.approx(summary["settle_time_s"], rel=0, abs=1e-9)
    assert r["max_penetration_recomputed"] == summary["max_penetration"]
    # the recorded couples applied the muscles' effort the simulator reported
    assert r["peak_couple_recomputed"] == summary["peak_couple"] > 0 and r["peak_couple_ratio"] is None
    # recomputation from the rod states matches the recorded contact and quality topics
    assert r["max_recompute_error"] is not None and r["max_recompute_error"] <= 1e-9
    assert r["recompute_errors"]["Q2_relative"] <= 1e-9
    assert r["recomputed_pairs"]["contact"] == summary["steps"] + 1
    assert r["recomputed_pairs"]["quality"] == r["messages"]["quality"] > 0
    assert r["recompute_mismatches"] == {"in_contact": 0, "valid": 0} and r["recompute_failures"] == []
    assert r["recompute_parameters"]["source"] == "run parameters"
    assert r["recompute_parameters"]["sensor_contact_tolerance"] == PAPER.sensing.contact_tolerance == 0.0005
    assert r["recompute_parameters"]["quality_contact_tolerance"] == -1.0  # the contact states' own: one contact set
    topics = {t["name"]: t for t in r["topics"]}
    assert topics[ROD]["count"] == summary["steps"] + 1 and topics[ROD]["type"] == "contgrasp_msgs/msg/RodState"
    assert r["recorder"]["received"] == r["recorder"]["written"] == summary["bag"]["messages"]
    assert r["recorded_sim_time_s"] == pytest.approx(summary["sim_time_s"], abs=1e-9)
    # one builder: every RunSummary key agrees between the launcher and the recording (the
    # wall-clock times only the launcher measures)
    for key in RunSummary.__dataclass_fields__:
        if key not in ("wall_time_s", "loop_wall_time_s", "real_time_factor", "step_wall_ms"):
            assert r[key] == summary[key], key
    assert r["wall_time_s"] is None and summary["wall_time_s"] > summary["loop_wall_time_s"] > 0
    assert r["real_time_factor"] is None and summary["real_time_factor"] == pytest.approx(
        summary["sim_time_s"] / summary["loop_wall_time_s"], rel=1e-12)
    assert summary["step_wall_ms"] == pytest.approx(1e3 * summary["loop_wall_time_s"] / summary["steps"], rel=1e-12)
    assert summary["contact_nodes"] > 0 and summary["contact_length"] > 0
    # the launcher records in simulated time: the recording spans the run's simulated time
    assert summary["bag"]["log_time_clock"] == "sim" and summary["bag"]["wall_time_s"] is None
    assert summary["bag"]["sim_time_s"] == pytest.approx(summary["sim_time_s"], abs=1e-6)


def test_cli_writes_csv_and_plots(recording: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag, summary = recording
    out, plot = tmp_path / "csv", tmp_path / "run.png"
    assert cli(str(bag), "--json", "--csv", str(out), "--plot", str(plot)) == 0
    r = json.loads(capsys.readouterr().out)
    n_nodes, n_states, n_quality = len(summary["final"]["s"]), summary["steps"] + 1, r["messages"]["quality"]
    tables = {}
    for name in ("rod_state", "contact", "quality"):
        with open(out / f"{name}.csv", newline="") as f:
            tables[name] = list(csv.DictReader(f))
        assert r["csv"][name]["rows"] == len(tables[name])
    assert len(tables["rod_state"]) == len(tables["contact"]) == n_states * n_nodes
    assert len(tables["quality"]) == n_quality
    assert list(tables["rod_state"][0]) == ["t", "step", "i", "s", "x", "y", "theta", "radius", "vx", "vy"]
    last = [row for row in tables["rod_state"] if int(row["step"]) == summary["steps"]]
    assert [float(row["x"]) for row in last] == summary["final"]["x"]  # round-trip exact
    q = tables["quality"][-1]
    assert float(q["q1"]) == summary["final_quality"]["Q1"] and float(q["recomputed_q1"]) == pytest.approx(float(q["q1"]), rel=1e-9)
    assert r["plot"] == {"figure": str(plot), "quality": str(tmp_path / "run_quality.png")}
    for p in (plot, tmp_path / "run_quality.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000


BLOCKED = ("rclpy", "rosidl_runtime_py", "rosidl_parser", "rosidl_pycommon", "contgrasp_msgs", "std_msgs",
           "builtin_interfaces", "diagnostic_msgs", "rosgraph_msgs", "visualization_msgs", "rcl_interfaces",
           "ament_index_python")


def test_analyze_runs_without_ros(recording: tuple[Path, dict], tmp_path: Path) -> None:
    """With every ROS package made unimportable, the CLI still analyses the recording."""
    bag, summary = recording
    code = (
        "import json, sys\n"
        f"for name in {BLOCKED!r}:\n"
        "    sys.modules[name] = None\n"
        "from contgrasp_core.cli import main\n"
        "from contgrasp_ros.recordings import cli_analyze\n"
        f"rc = main(['analyze', {str(bag)!r}, '--json', '--plot', {str(tmp_path / 'p.png')!r}], extra=[cli_analyze.add_parser])\n"
        "leaked = sorted(m for m in sys.modules if m.split('.')[0] in " + repr(BLOCKED) + " and sys.modules[m] is not None)\n"
        "print(json.dumps({'leaked': leaked}))\n"
        "sys.exit(rc)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "PYTHONPATH")}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result_line, leaked_line = proc.stdout.strip().splitlines()
    r = json.loads(result_line)
    assert json.loads(leaked_line) == {"leaked": []}
    assert r["settle_time_s"] == summary["settle_time_s"] and r["max_recompute_error"] <= 1e-9
    assert r["plot"]["figure"] and r["plot"]["quality"]


def decimate(src: Path, dst: Path, period: float = 0.05) -> list[int]:
    """A copy keeping rod state/contact/couple once per ``period`` of stamp time plus each
    topic's last message (like the recorder's decimation); returns the kept rod-state steps."""
    rec = open_recording(src)
    stamps = {}
    for raw, msg in iter_decoded(rec, [ROD, CONTACT, COUPLE]):
        stamps[(raw.topic, raw.log_time_ns, raw.sequence)] = (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec, int(msg.step))
    last_of = {}
    for key in stamps:
        last_of[key[0]] = key
    kept_at: dict[str, float] = {}
    kept_steps = []

    def kept(m: Any) -> bool:
        key = (m.topic, m.log_time_ns, m.sequence)
        if key in stamps:
            t, step = stamps[key]
            if key != last_of[m.topic] and m.topic in kept_at and t - kept_at[m.topic] < period - 1e-12:
                return False
            kept_at[m.topic] = t
            if m.topic == ROD:
                kept_steps.append(step)
        return True

    copy_recording(rec, dst, (as_is(m) for m in iter_raw(rec) if kept(m)))
    return kept_steps


def test_decimated_recording_pairs_by_step(recording: tuple[Path, dict], tmp_path: Path) -> None:
    bag, summary = recording
    kept = decimate(bag, tmp_path / "dec")
    assert 5 < len(kept) < summary["steps"] // 5
    r = analyze(tmp_path / "dec")
    full = analyze(bag)
    for key in ("settled", "settle_time_s", "steps", "final", "final_quality", "mean_abs_rho_ratio_minus_1_contact"):
        assert r[key] == full[key], key
    gaps = r["step_gaps"]
    assert not gaps["contiguous"] and gaps["rod_states"] == len(kept) and gaps["missing_steps"] == summary["steps"] + 1 - len(kept)
    assert r["settle_time_recomputed_s"] is None and r["settled_recomputed"] is None
    assert r["max_penetration_recomputed"] is None
    assert r["recomputed_pairs"]["contact"] == len(kept)
    assert 0 < r["recomputed_pairs"]["quality"] <= r["messages"]["quality"] == full["messages"]["quality"]
    assert r["max_recompute_error"] <= 1e-9


def test_streams_are_read_in_publish_order(recording: tuple[Path, dict], tmp_path: Path) -> None:
    """A message logged out of its publish order (a late quality of step 0 is stamped t = 0,
    which the recorder logs at its clock on arrival) does not become the run's last one."""
    bag, summary = recording
    rec = open_recording(bag)
    first_quality = min(iter_raw(rec, [QUALITY]), key=lambda m: m.publish_time_ns)
    end_ns = max(m.log_time_ns for m in iter_raw(rec))
    late = {(QUALITY, first_quality.publish_time_ns)}
    copy_recording(rec, tmp_path / "late", ((m.topic, m, m.data, end_ns + 1 if (m.topic, m.publish_time_ns) in late else m.log_time_ns,
                                             m.publish_time_ns) for m in iter_raw(rec)))
    last_logged = list(iter_raw(open_recording(tmp_path / "late"), [QUALITY]))[-1]
    assert last_logged.publish_time_ns == first_quality.publish_time_ns  # (the copy does reorder)
    assert analyze(tmp_path / "late")["final_quality"] == analyze(bag)["final_quality"] == summary["final_quality"]


def test_a_state_published_again_is_analysed_once(recording: tuple[Path, dict], tmp_path: Path) -> None:
    """The simulator sends a state the loop waits on again (a peer joined after it went out) and
    the sensor its answer: recorded twice in a row, analysed once, the recording still complete."""
    bag, summary = recording
    rec = open_recording(bag)
    repeated = {ROD: 0, CONTACT: 0}

    def again(m: Any) -> Iterator[tuple[str, Any, bytes, int, int]]:
        yield as_is(m)
        if m.topic in repeated and repeated[m.topic] < 3:  # (steps 0, 1, 2, each once more)
            yield m.topic, m, m.data, m.log_time_ns, m.publish_time_ns + 1
            repeated[m.topic] += 1

    copy_recording(rec, tmp_path / "again", (row for m in sorted(iter_raw(rec), key=lambda m: m.publish_time_ns) for row in again(m)))
    r, full = analyze(tmp_path / "again"), analyze(bag)
    assert r["step_gaps"] == {**full["step_gaps"], "repeated_states": 3} and r["step_gaps"]["contiguous"]
    for key in ("settled_recomputed", "settle_time_recomputed_s", "recomputed_pairs", "max_recompute_error", "final"):
        assert r[key] == full[key], key


def test_recomputation_is_not_vacuous(recording: tuple[Path, dict]) -> None:
    """A perturbed rod state, a wrong sensor tolerance or a wrong quality tolerance shows up."""
    bag, _ = recording
    run = load_run(bag)
    assert recompute(run).max_error <= 1e-9
    # the state of the last quality evaluation (the arm wraps the object by then)
    k = int(np.flatnonzero(run.rod.step == run.quality.step[-1])[0])
    run.rod.x[k] += 1e-4
    rc = recompute(run)
    assert rc.errors["rho"] > 1e-5 and rc.errors["Q1"] > 0.0
    run = load_run(bag)
    assert recompute(run, sensor_tolerance=2e-3).in_contact_mismatches > 0
    assert recompute(run, quality_tolerance=0.0).errors["Q1"] > 1e-9


def test_contact_stats() -> None:
    """Every statistic names its contact set (nodes and length); the tracking error is given as
    mean and max over it."""
    s, rho, delta, alpha = [0.0, 0.01, 0.02, 0.03], [0.02, 0.011, 0.0105, 0.05], [-0.01, -0.001, -0.0005, -0.04], [1.0, 1.5, 1.6, 2.0]
    stats = contact_stats(s, rho, delta, alpha, [False, True, True, False], tol=0.001)
    assert stats.mean_abs_rho_ratio_minus_1_contact == pytest.approx((0.1 + 0.05) / 2)
    assert stats.max_abs_rho_ratio_minus_1_contact == pytest.approx(0.1)
    assert stats.mean_abs_alpha_minus_half_pi_contact == pytest.approx((np.pi / 2 - 1.5 + 1.6 - np.pi / 2) / 2)
    assert stats.max_abs_alpha_minus_half_pi_contact == pytest.approx(np.pi / 2 - 1.5)
    assert stats.contact_nodes == 2
    # the contact length is the quality evaluator's: delta >= -tol cut at the linear crossing
    from contgrasp_core.quality import contact_weights

    assert stats.contact_length == pytest.approx(contact_weights(s, delta, 0.001).sum()) and 0.01 < stats.contact_length < 0.03
    assert contact_stats(s, rho, [-1.0] * 4, alpha, [False] * 4) == ContactStats(None, None, None, None, 0, 0.0)
    assert contact_stats(None) == ContactStats()  # no contact state at all
    assert ContactStats().contact_nodes is None and ContactStats().contact_length is None


def test_summary_builder_reads_the_simulator_status() -> None:
    """One builder for the launcher and analyze: the simulator's and the controller's /diagnostics
    values parsed, missing or garbled ones None/0, a movable object's motion as simulate's keys,
    the JSON keys the field names."""
    status = {"state": "finished", "settled": "true", "settle_time_s": "1.5", "sim_time_s": "2.0", "step": "1000",
              "missed_deadlines": "3", "max_penetration": "nan?"}
    final = FinalState.of(1000, 2.0, np.array([0.0, 0.1]), [0.0, 0.1], (0.0, 0.0), np.zeros(2))
    s = build_summary(status, final=final, final_quality=FinalQuality.of(np.float64(1.0), 2.0, 0.5, np.bool_(True), 0.1, np.int64(950)),
                      contact=contact_stats(None), controller={"law": "reactive", "law_phase": "close"},
                      object_q=np.array([1e-3, -2e-3, 0.01]), object_v=(0.0, 0.5, -1.0), wall_time_s=4.0)
    d = s.to_dict()
    assert d["simulator_state"] == "finished" and d["settled"] is True and d["settle_time_s"] == 1.5
    assert d["steps"] == 1000 and d["missed_deadlines"] == 3 and d["max_penetration"] is None
    assert d["final"] == {"step": 1000, "t": 2.0, "s": [0.0, 0.1], "x": [0.0, 0.1], "y": [0.0, 0.0], "theta": [0.0, 0.0]}
    assert d["law"] == "reactive" and d["law_phase"] == "close"
    assert d["object_displacement"] == {"x": 1e-3, "y": -2e-3, "angle": 0.01}
    assert d["object_velocity"] == {"x": 0.0, "y": 0.5, "angle": -1.0}
    assert d["final_quality"] == {"Q1": 1.0, "Q2": 2.0, "Q3": 0.5, "valid": True, "contact_length": 0.1, "step": 950}
    assert d["wall_time_s"] == 4.0 and d["loop_wall_time_s"] is None and d["contact_nodes"] is None
    assert list(d) == [f.name for f in fields(RunSummary)]
    json.dumps(d, allow_nan=False)  # plain JSON types
    empty = build_summary({}, final=None, final_quality=None, contact=ContactStats()).to_dict()
    assert empty["simulator_state"] == "unknown" and empty["settled"] is False and empty["steps"] == 0
    assert empty["final"] is None and empty["sim_time_s"] is None
    assert empty["law"] is None and empty["law_phase"] is None  # (no controller status)
    assert empty["object_displacement"] is None and empty["object_velocity"] is None  # (a fixed object)
    paper = build_summary({}, final=None, final_quality=None, contact=ContactStats(), controller={"law": "paper", "law_phase": ""},
                          object_q=[], object_v=[]).to_dict()
    assert paper["law"] == "paper" and paper["law_phase"] is None and paper["object_displacement"] is None


def test_an_interrupted_runs_steps_are_its_last_states() -> None:
    """Ctrl-C stops a run between two statuses (one every 0.2 s of wall time at most): its last
    status says step 394 while the last rod state is step 400 and the quality was evaluated
    there. The summary's steps and simulated time are the newest."""
    status = {"state": "running", "sim_time_s": "0.788", "step": "394"}
    final = FinalState.of(400, 0.8, [0.0, 0.1], [0.0, 0.1], [0.0, 0.0], [0.0, 0.0])
    d = build_summary(status, final=final, final_quality=FinalQuality.of(1.0, 2.0, 0.5, True, 0.1, 400),
                      contact=contact_stats(None), loop_wall_time_s=2.0).to_dict()
    assert d["steps"] == d["final"]["step"] == d["final_quality"]["step"] == 400
    assert d["sim_time_s"] == 0.8 and d["real_time_factor"] == 0.4 and d["step_wall_ms"] == 5.0
    assert d["simulator_state"] == "running"


def test_bad_input_is_one_line_and_exit_code_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli(str(tmp_path / "missing")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("contgrasp analyze: error: no recording at")

    w = BagWriter(tmp_path / "strings")
    w.add_topic("/chatter", "std_msgs/msg/String", definition="string data\n")
    cdr = b"\x00\x01\x00\x00" + (3).to_bytes(4, "little") + b"hi\x00"
    for i in range(3):
        w.write("/chatter", cdr, 1000 + i)
    w.close()
    assert cli(str(tmp_path / "strings")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no /contgrasp/rod_state messages" in err and "/chatter (3)" in err

    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    assert cli(str(junk)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not an MCAP file" in err


def test_truncated_recording_is_reported(recording: tuple[Path, dict], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag, _ = recording
    data = (bag / "run_0.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert cli(str(cut)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "incomplete" in err


def test_holding_under_pushes_recovers_a_known_compliance() -> None:
    """A synthetic recording of an object that answers a force step and a later torque pulse
    with known static compliances (and rests before each push): the analysis finds both pushes
    and their compliances exactly."""
    import numpy as np

    from contgrasp_ros.recordings.analysis import holding_under_pushes

    t = np.arange(100) * 0.01
    wrench = np.zeros((100, 3))
    wrench[20:50] = (0.03, -0.04, 0.0)
    wrench[70:80] = (0.0, 0.0, 2e-4)
    q = np.zeros((100, 3))
    q[20:50, :2] = 0.002 * wrench[20:50, :2] / 0.05**2 * (1 - np.exp(-(t[20:50, None] - 0.2) / 0.05))
    q[49:70, :2] = q[49, :2]
    q[70:80, 2] = 3.0 * 2e-4
    v = np.gradient(q, t, axis=0)
    pushes = holding_under_pushes(t, q, v, wrench)
    assert [p["t_start"] for p in pushes] == [t[20], t[70]]
    expected = float(q[49, :2] @ wrench[20, :2] / (0.05**2))
    assert abs(pushes[0]["compliance_force"] - expected) < 1e-15 and pushes[0]["compliance_torque"] is None
    assert abs(pushes[1]["compliance_torque"] - 3.0) < 1e-12 and pushes[1]["compliance_force"] is None


def test_a_recording_without_run_parameters_still_replays_the_settle_rule(recording: tuple[Path, dict], tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A run started by hand records no run parameters (no launcher): with every rod state from
    step 0 the settle rule is still replayed, with the node defaults, and the report says so
    (not ``settled_recomputed: None`` beside ``step_gaps.contiguous: true``).
    Truth: the simulator's own verdict, once the fixture's looser rule stands in as the defaults."""
    from contgrasp_ros.bag.writer import RUN_RECORD
    from contgrasp_ros.recordings import recompute as recomputation

    bag, summary = recording
    rec = open_recording(bag)
    copy = tmp_path / "by_hand.mcap"
    copy_recording(rec, copy, (as_is(m) for m in iter_raw(rec)), dropped_records=(RUN_RECORD,))
    r = analyze(copy)
    assert r["step_gaps"]["contiguous"] and r["recompute_parameters"]["source"].startswith("recorded messages and node defaults")
    assert r["recompute_parameters"]["settle_speed"] == PAPER.loop.settle_speed
    assert isinstance(r["settled_recomputed"], bool)
    fixture_rule = {"settle_speed": 0.05, "settle_hold": 0.04, "min_time": 0.2}  # (the recording fixture's)
    default = recomputation.node_default
    monkeypatch.setattr(recomputation, "node_default", lambda node, key: fixture_rule.get(key, default(node, key))
                        if node == recomputation.SIMULATOR else default(node, key))
    r = analyze(copy)
    assert r["settled_recomputed"] is True
    assert r["settle_time_recomputed_s"] == pytest.approx(summary["settle_time_s"], rel=0, abs=1e-9)


def test_a_recording_made_under_a_namespace_is_analysed_as_its_graph(recording: tuple[Path, dict], tmp_path: Path) -> None:
    """The fixture's run as a graph under ``/r1`` would have recorded it (its topics and clock under
    ``/r1``, the simulator's status named ``r1/rod_simulator`` on the global ``/diagnostics``):
    analysed the same, the namespace found from the topic names."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message

    bag, _ = recording
    rec = open_recording(bag)
    moved = tmp_path / "r1.mcap"
    def under_r1(m: Any) -> tuple[str, Any, bytes, int, int]:
        topic, data = ("/r1" + m.topic if m.topic.startswith(("/contgrasp/", "/clock")) else m.topic), m.data
        if m.topic == "/diagnostics":
            msg = deserialize_message(m.data, DiagnosticArray)
            for st in msg.status:
                st.name = "r1/" + st.name
            data = serialize_message(msg)
        return topic, m, data, m.log_time_ns, m.publish_time_ns

    copy_recording(rec, moved, (under_r1(m) for m in iter_raw(rec)))
    r, full = analyze(moved), analyze(bag)
    assert ROD not in {t["name"] for t in r["topics"]} and "/r1" + ROD in {t["name"] for t in r["topics"]}
    for key in ("simulator_state", "settled", "steps", "missed_deadlines", "final", "final_quality", "max_recompute_error",
                "recomputed_pairs", "step_gaps"):
        assert r[key] == full[key], key
    assert full["simulator_state"] == "finished"


def test_concurrent_processes_are_overlapping_status_spans() -> None:
    """Two processes of one status name at once are listed; one after another (a restart) not."""
    from contgrasp_ros.recordings.run_data import concurrent_processes

    assert concurrent_processes({}) == []
    restarted = {"rod_simulator": {7: (0, 100), 9: (150, 300)}, "grasp_controller": {8: (0, 300)}}
    assert concurrent_processes(restarted) == []
    twice = {"rod_simulator": {9: (50, 300), 7: (0, 100), 11: (310, 400)}}
    assert concurrent_processes(twice) == [{"node": "rod_simulator", "pids": [7, 9]}]
    same_instant = {"r1/grasp_quality": {5: (0, 100), 6: (100, 200)}}
    assert concurrent_processes(same_instant) == [{"node": "r1/grasp_quality", "pids": [5, 6]}]


def test_a_recording_beside_another_graph_fails_and_a_restart_passes(recording: tuple[Path, dict], tmp_path: Path) -> None:
    """The fixture's recording with a second simulator's statuses beside its own (another graph
    in the domain: a pid the run never had, at the same times) fails with exit 1 after its
    result; with its simulator's statuses from a new pid after the middle of the run (a restart,
    the processes one after another) it analyses as the original."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message

    bag, _ = recording
    rec = open_recording(bag)
    diags = [m for m in iter_raw(rec) if m.topic == "/diagnostics"]
    middle = sorted(m.publish_time_ns for m in diags)[len(diags) // 2]
    own_pid = None

    def with_pid(m: Any, pid: int) -> bytes:
        nonlocal own_pid
        msg = deserialize_message(m.data, DiagnosticArray)
        msg.status = [st for st in msg.status if st.name == "rod_simulator"]
        for st in msg.status:
            for kv in st.values:
                if kv.key == "pid":
                    own_pid, kv.value = int(kv.value), str(pid)
        return serialize_message(msg)

    def beside(m: Any) -> Iterator[tuple[str, Any, bytes, int, int]]:
        yield as_is(m)
        if m.topic == "/diagnostics":
            yield m.topic, m, with_pid(m, 4_000_001), m.log_time_ns, m.publish_time_ns + 1

    def restarted(m: Any) -> tuple[str, Any, bytes, int, int]:
        if m.topic == "/diagnostics" and m.publish_time_ns > middle:
            msg = deserialize_message(m.data, DiagnosticArray)
            for st in msg.status:
                for kv in st.values:
                    if st.name == "rod_simulator" and kv.key == "pid":
                        kv.value = "4000002"
            return m.topic, m, serialize_message(msg), m.log_time_ns, m.publish_time_ns
        return as_is(m)

    copy_recording(rec, tmp_path / "beside.mcap", (row for m in iter_raw(rec) for row in beside(m)))
    copy_recording(rec, tmp_path / "restarted.mcap", (restarted(m) for m in iter_raw(rec)))
    full = analyze(bag)
    assert full["concurrent_processes"] == [] and own_pid is not None

    mixed = analyze(tmp_path / "beside.mcap")
    assert mixed["concurrent_processes"] == [{"node": "rod_simulator", "pids": [own_pid, 4_000_001]}]
    with pytest.raises(MixedRecordingError, match=rf"statuses of rod_simulator from pids {own_pid} and 4000001 at once"):
        check(mixed)
    assert cli(str(tmp_path / "beside.mcap"), "--json") == 1

    again = analyze(tmp_path / "restarted.mcap")
    assert again["concurrent_processes"] == []
    check(again)
    for key in ("simulator_state", "settled", "steps", "final", "final_quality", "max_recompute_error", "step_gaps"):
        assert again[key] == full[key], key


def test_the_settle_replay_of_a_run_outside_the_models_validity_is_not_settled(recording: tuple[Path, dict],
                                                                             tmp_path: Path) -> None:
    """The fixture's recording with its simulator's verdict turned to 'left the model's
    validity' (as an arm inside its object reports it): the replayed rule, quiet as the states
    are, is not settled either, as the simulator's own (settled and valid). Before, the replay
    said settled at 1.878 s beside the simulator's 'not settled' on such a run."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message

    bag, summary = recording
    assert summary["settled"] and analyze(bag)["settled_recomputed"] is True
    rec = open_recording(bag)

    def invalid(m: Any) -> tuple[str, Any, bytes, int, int]:
        if m.topic != "/diagnostics":
            return as_is(m)
        msg = deserialize_message(m.data, DiagnosticArray)
        for st in msg.status:
            for kv in st.values:
                if st.name == "rod_simulator" and kv.key == "validity":
                    kv.value = json.dumps({**json.loads(kv.value), "valid": False})
        return m.topic, m, serialize_message(msg), m.log_time_ns, m.publish_time_ns

    copy_recording(rec, tmp_path / "invalid.mcap", (invalid(m) for m in iter_raw(rec)))
    r = analyze(tmp_path / "invalid.mcap")
    assert r["validity"]["valid"] is False
    assert (r["settled_recomputed"], r["settle_time_recomputed_s"]) == (False, None)
