"""The graph end to end: `ros2 run` lookup, in-process and multi-process runs, determinism."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("contgrasp_msgs.msg")

from contgrasp_core.errors import InvalidParameterError  # noqa: E402
from contgrasp_core.rod.session import run_sampled  # noqa: E402
from contgrasp_core.scenario import Scenario  # noqa: E402
from contgrasp_ros.launcher.events import read_events  # noqa: E402
from contgrasp_ros.launcher.cli import default_params_file, load_params  # noqa: E402

from conftest import fresh_domain_id  # noqa: E402

BIN = Path(sys.executable).parent


def small_params(tmp_path: Path, duration: float = 0.1) -> Path:
    """The packaged scenario, shortened and coarsened so a run takes seconds."""
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = 20
    data["rod_simulator"]["ros__parameters"]["duration"] = duration
    data["rod_simulator"]["ros__parameters"]["marker_period"] = 0.02
    data["grasp_quality"]["ros__parameters"]["rate_hz"] = 0.0
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def core_run(params_file: Path) -> tuple[np.ndarray, int]:
    """The same scenario with the core functions only (no ROS)."""
    session = run_sampled(Scenario.from_ros_parameters(load_params(params_file)))
    obs = session.observe()
    return obs.x, obs.k


def launch(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return subprocess.run([str(BIN / "contgrasp-launch"), "--domain-id", str(fresh_domain_id()), *args],
                          capture_output=True, text=True, timeout=timeout, env=env)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.heavy
def test_ros2_run_finds_and_runs_the_executables() -> None:
    """The lookup `ros2 run contgrasp_ros <node>` performs: ament index prefix, then lib/<pkg>/<node>."""
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    prefix = Path(get_package_prefix("contgrasp_ros"))
    assert (Path(get_package_share_directory("contgrasp_ros")) / "package.xml").exists()
    for node in ("rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality", "mcap_recorder", "container"):
        exe = prefix / "lib" / "contgrasp_ros" / node
        assert exe.exists() and os.access(exe, os.X_OK), exe
    env = dict(os.environ, ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    exe = prefix / "lib" / "contgrasp_ros" / "boundary_sensor"
    bad = subprocess.run([str(exe), "--ros-args", "-p", "contact_tolerance:=-1.0"], capture_output=True, text=True,
                         timeout=60, env=env)
    assert bad.returncode == 2 and "contact_tolerance" in bad.stderr
    proc = subprocess.Popen([str(exe)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    time.sleep(3.0)
    assert proc.poll() is None  # running
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) == 0


@pytest.mark.heavy
def test_graph_in_process_equals_the_core_loop(tmp_path: Path) -> None:
    params = small_params(tmp_path)
    events = tmp_path / "events.jsonl"
    proc = launch("--in-process", "--json", "--params", str(params), "--bag", str(tmp_path / "inproc.mcap"), "--events", str(events))
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout)
    # in-process: no node processes, so only the launcher's own events
    got = list(read_events(events.read_text().splitlines()))
    assert [e["event"] for e in got] == ["domain_id", "resumed", "finished"]
    assert got[0] == {**got[0], "domain_id": out["domain_id"], "mode": "in-process"}
    assert got[-1]["exit_code"] == 0 and got[-1]["error"] is None
    assert out["missed_deadlines"] == 0
    assert out["bag"]["received"] == out["bag"]["written"] == out["bag"]["messages"] > 0
    assert out["bag"]["topics"]["/contgrasp/rod_state"] == out["steps"] + 1
    x_core, k = core_run(params)
    assert out["steps"] == k
    np.testing.assert_allclose(out["final"]["x"], x_core[:, 0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["final"]["y"], x_core[:, 1], rtol=0, atol=1e-9)
    assert out["final_quality"] is not None


@pytest.mark.heavy
def test_graph_as_processes_is_deterministic_and_leaves_nothing_behind(tmp_path: Path) -> None:
    params = small_params(tmp_path)
    runs = []
    for i in range(2):
        proc = launch("--json", "--params", str(params), *(("--bag", str(tmp_path / "bag")) if i == 0 else ("--no-record",)))
        assert proc.returncode == 0, proc.stderr[-3000:]
        out = json.loads(proc.stdout)
        assert set(out["exit_codes"]) == {"rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality"} | (
            {"mcap_recorder"} if i == 0 else set())
        assert all(code == 0 for code in out["exit_codes"].values()), out["exit_codes"]
        assert not any(alive(pid) for pid in out["pids"].values())
        runs.append(out)
    x_core, k = core_run(params)
    for out in runs:
        assert out["steps"] == k and out["missed_deadlines"] == 0
        np.testing.assert_allclose(out["final"]["x"], x_core[:, 0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(out["final"]["y"], x_core[:, 1], rtol=0, atol=1e-9)
    assert runs[0]["final"] == runs[1]["final"]


@pytest.mark.heavy
def test_composed_nodes_run_the_same_graph_in_fewer_processes(tmp_path: Path) -> None:
    """--compose: the sensor, the controller and the quality node hosted by one process
    (contgrasp_ros.nodes.container) give the core loop's run bit for bit, the process exits 0 under
    its composed name, and the graph still has every node (the quality node answered)."""
    params = small_params(tmp_path)
    proc = launch("--json", "--no-record", "--params", str(params), "--compose", "boundary_sensor,grasp_controller,grasp_quality")
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout)
    assert out["exit_codes"] == {"rod_simulator": 0, "boundary_sensor+grasp_controller+grasp_quality": 0}
    assert not any(alive(pid) for pid in out["pids"].values())
    x_core, k = core_run(params)
    assert out["steps"] == k and out["missed_deadlines"] == 0
    np.testing.assert_array_equal(out["final"]["x"], x_core[:, 0])
    np.testing.assert_array_equal(out["final"]["y"], x_core[:, 1])
    assert out["final_quality"] is not None


@pytest.mark.heavy
def test_launcher_reports_a_node_that_fails_to_start(tmp_path: Path) -> None:
    """An invalid parameter stops that node at start-up (exit 2); the launcher names it, stops
    the others and exits non-zero with the failing node's code."""
    data = yaml.safe_load(small_params(tmp_path).read_text())
    data["grasp_quality"]["ros__parameters"]["rate_hz"] = -5.0
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    proc = launch("--json", "--params", str(bad), "--timeout", "120", "--no-record")
    assert proc.returncode == 2, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    assert "grasp_quality" in out["error"] and "code 2" in out["error"]
    assert out["exit_codes"]["grasp_quality"] == 2
    assert "rate_hz" in proc.stderr
    assert not any(alive(pid) for pid in out["pids"].values())


@pytest.mark.heavy
@pytest.mark.parametrize("node", ["rod_simulator", "grasp_controller"])
def test_a_second_graph_in_the_same_domain_and_namespace_fails_the_run(tmp_path: Path, node: str) -> None:
    """A node of another graph (here one started by hand: a simulator, a controller) in the
    launcher's domain and namespace: each controller would answer both simulators, so the launcher
    ends its run with one line naming that process and what to do, stops its own nodes and leaves
    the other alone."""
    domain = fresh_domain_id()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain))
    other = subprocess.Popen([sys.executable, "-m", f"contgrasp_ros.nodes.{node}"], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        proc = launch("--json", "--params", str(small_params(tmp_path, duration=5.0)), "--no-record",
                      "--domain-id", str(domain))
        assert other.poll() is None  # (still running: the launcher stops only what it started)
    finally:
        other.send_signal(signal.SIGINT)
        other.wait(timeout=30)
    assert proc.returncode == 1, proc.stderr[-3000:]
    out = json.loads(proc.stdout)
    assert out["error"] == (f"another graph's {node} (pid {other.pid}) runs in this domain and namespace, so "
                            "the two runs' messages mix: give each graph its own --namespace or --domain-id")
    assert proc.stderr.splitlines()[-1] == f"contgrasp-launch: error: {out['error']}"
    # stopped, not failed (a node whose interpreter is still starting, before Python handles SIGINT, ends by the signal itself)
    assert all(code in (0, -signal.SIGINT) for code in out["exit_codes"].values()), out["exit_codes"]
    assert not any(alive(pid) for pid in out["pids"].values())


@pytest.mark.parametrize(("exc", "code", "prefix"), [(RuntimeError("rmw said no\nsecond line"), 1, "error: RuntimeError: "),
                                                    (InvalidParameterError("n_elements must be >= 2"), 2, "error: ")])
def test_launcher_turns_unexpected_errors_into_one_line(monkeypatch, capsys, exc, code, prefix) -> None:  # type: ignore[no-untyped-def]
    """An exception out of the graph run is one line on stderr (exit 1, or 2 for bad input);
    --debug shows the traceback instead, with the same code."""
    import contgrasp_ros.launcher.graph_run
    from contgrasp_ros.launcher import cli as launcher

    def broken(*_a: object, **_k: object) -> None:
        raise exc

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", broken)
    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(var, os.environ.get(var, "0"))
    assert launcher.main(["--no-record", "--domain-id", str(fresh_domain_id())]) == code
    err = [line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("[launcher] ")]
    assert err == [f"contgrasp-launch: {prefix}{' | '.join(str(exc).splitlines())}"]
    assert launcher.main(["--no-record", "--debug", "--domain-id", str(fresh_domain_id())]) == code
    assert "Traceback (most recent call last):" in capsys.readouterr().err


def test_node_processes_get_the_discovery_profile_and_the_launcher_keeps_its_environment(monkeypatch, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """The node processes' environment names the packaged Fast DDS profile (more initial discovery
    announcements: processes started together meet at once); the launcher's own is unchanged."""
    import xml.etree.ElementTree as ET

    import contgrasp_ros.launcher.processes
    from contgrasp_ros.launcher.discovery import discovery_profile
    from contgrasp_ros.launcher.graph_run import run_graph

    seen: list[dict[str, str]] = []

    class Started(Exception):
        pass

    def group(env: dict[str, str], **_k: object) -> None:
        seen.append(env)
        raise Started

    monkeypatch.setattr(contgrasp_ros.launcher.processes, "ProcessGroup", group)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(fresh_domain_id()))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    before = os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE")
    params = small_params(tmp_path)
    with pytest.raises(Started):
        run_graph(load_params(params), in_process=False, params_file=params, timeout=10.0)
    assert os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") == before
    if not (before or os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE")):
        assert seen[0]["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(discovery_profile())
    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    count = ET.parse(discovery_profile()).find(".//f:initialAnnouncements/f:count", ns)
    assert count is not None and int(count.text or 0) > 5


def test_the_discovery_profile_is_used_unless_one_is_named() -> None:
    """The launcher's rule (contgrasp_ros.launcher.discovery): the packaged profile unless the environment
    names one."""
    from contgrasp_ros.launcher.discovery import discovery_profile, discovery_profile_set, use_discovery_profile

    env: dict[str, str] = {}
    use_discovery_profile(env)
    assert env == {"FASTRTPS_DEFAULT_PROFILES_FILE": str(discovery_profile())} and discovery_profile().is_file()
    for name in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        own = {name: "/elsewhere/profile.xml"}
        use_discovery_profile(own)
        assert own == {name: "/elsewhere/profile.xml"}
    with discovery_profile_set(env := {"OTHER": "1"}):
        assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(discovery_profile())
    assert env == {"OTHER": "1"}


@pytest.mark.heavy
def test_launcher_rejects_bad_usage(tmp_path: Path) -> None:
    assert launch("--duration", "-1").returncode == 2
    bad = tmp_path / "bad.yaml"
    bad.write_text("- not a mapping\n")
    assert launch("--params", str(bad)).returncode == 2
    data = yaml.safe_load(small_params(tmp_path).read_text())
    data["rod_simulator"]["ros__parameters"]["settle_hold"] = 1  # an int where a float is declared
    bad.write_text(yaml.safe_dump(data))
    proc = launch("--in-process", "--no-record", "--json", "--params", str(bad))
    assert proc.returncode == 2 and "settle_hold" in json.loads(proc.stdout)["error"], proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert launch("--executor", "events").returncode == 2  # events executor: in-process only
    for compose in (["rod_simulator,boundary_sensor"], ["boundary_sensor"], ["boundary_sensor,planner"],
                    ["boundary_sensor,grasp_controller", "grasp_controller,grasp_quality"],
                    ["boundary_sensor,boundary_sensor"]):
        proc = launch(*(a for c in compose for a in ("--compose", c)))
        assert proc.returncode == 2 and "--compose" in proc.stderr and "Traceback" not in proc.stderr, compose
    proc = launch("--in-process", "--compose", "boundary_sensor,grasp_controller")
    assert proc.returncode == 2 and "--in-process" in proc.stderr
    for timeout in ("0", "-5", "nan", "inf"):  # (--timeout 0 once ran and failed with 68 lines; -5, nan were accepted)
        proc = launch("--timeout", timeout)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and "--timeout" in lines[0], (timeout, proc.stderr[-2000:])
    for bad_split in (["--max-bag-duration", "nan"], ["--max-bag-size", "1000"],
                      ["--bag", str(tmp_path / "one.mcap"), "--max-bag-duration", "5"]):
        proc = launch(*bad_split)
        assert proc.returncode == 2 and "--max-bag" in proc.stderr and "Traceback" not in proc.stderr, bad_split


@pytest.mark.heavy
def test_text_summary_reads_like_the_contgrasp_subcommands(tmp_path: Path) -> None:
    """Without --json the launcher prints ``key.sub: value`` lines, floats to 6 significant digits,
    as every ``contgrasp`` subcommand does: no Python dict, no 15-digit float."""
    proc = launch("--in-process", "--no-record", "--params", str(small_params(tmp_path)))
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    values = dict(line.split(": ", 1) for line in lines)
    assert values["settled"] in ("True", "False") and float(values["sim_time_s"]) == pytest.approx(0.1)
    assert any(key.startswith("final_quality.") for key in values)
    for line in lines:
        assert "{" not in line, line
        for word in line.split(": ", 1)[1].strip("[]").split(", "):
            mantissa = word.lower().split("e")[0].lstrip("-").replace(".", "").lstrip("0")
            assert not word[:1].isdigit() or len(mantissa) <= 6, line


def test_the_monitor_keeps_its_own_nodes_statuses_and_names_another(ros_context) -> None:  # type: ignore[no-untyped-def]
    """Every node's status carries its pid: the launcher's monitor takes the statuses of processes
    it started (a restarted one too) and names a graph node's status from any other process
    (another graph's) without taking its values; a status without a pid (an older recording
    replayed) is taken; other nodes' statuses are none of its business."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from contgrasp_ros.launcher.graph_run import Monitor

    def status(name: str, state: str, pid: str | None) -> DiagnosticArray:
        values = [KeyValue(key="state", value=state)] + ([KeyValue(key="pid", value=pid)] if pid is not None else [])
        return DiagnosticArray(status=[DiagnosticStatus(name=name, values=values)])

    own = {100}
    monitor = Monitor(history_period=None, own_pids=lambda: own, context=ros_context)
    try:
        monitor._on_diag(status("rod_simulator", "running", "100"))
        monitor._on_diag(status("some_other_node", "x", "999"))
        assert monitor.status == {"state": "running", "pid": "100"} and monitor.foreign is None
        monitor._on_diag(status("rod_simulator", "finished", "200"))
        assert monitor.status["state"] == "running" and monitor.foreign == ("rod_simulator", 200)
        monitor._on_diag(status("grasp_quality", "ok", "201"))
        assert monitor.foreign == ("grasp_quality", 201)
        own.add(300)  # (restarted)
        monitor._on_diag(status("rod_simulator", "paused", "300"))
        monitor._on_diag(status("rod_simulator", "finished", None))
        assert monitor.status == {"state": "finished"}
    finally:
        monitor.destroy_node()


def test_the_monitor_pairs_each_contact_sample_with_the_rod_state_of_its_step_in_any_order(ros_context) -> None:  # type: ignore[no-untyped-def]
    """The figure's history starts at step 0 even when the contact sample of a step comes before
    its rod state (two topics: no order between them); one entry per history period."""
    from contgrasp_msgs.msg import ContactState, RodState

    from contgrasp_ros.launcher.graph_run import Monitor

    def rod(step: int) -> RodState:
        return RodState(step=step, s=[0.0, 0.1], x=[0.0, 0.1 + step], y=[0.0, 0.0], theta=[0.0] * 2, radius=[0.01] * 2)

    def contact(step: int) -> ContactState:
        msg = ContactState(step=step, s=[0.0, 0.1], rho=[0.05, 0.02 + step], alpha=[1.0, 1.5])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(step * 2_000_000, 1_000_000_000)
        return msg

    monitor = Monitor(history_period=0.01, context=ros_context)
    try:
        monitor._on_contact(contact(0))  # before its rod state
        monitor._on_rod(rod(0))
        for step in range(1, 12):  # in order: the rod state first (steps 5 and 10 enter the history)
            monitor._on_rod(rod(step))
            monitor._on_contact(contact(step))
        monitor._on_rod(rod(15))  # the rod state of step 15 before that of 16, whose contact comes first
        monitor._on_contact(contact(16))
        monitor._on_rod(rod(16))
        assert [(h["t"], h["x"][1], h["rho"][1]) for h in monitor.history] == [
            (0.0, 0.1, 0.02), (0.01, 5.1, 5.02), (0.02, 10.1, 10.02), (0.032, 16.1, 16.02)]
    finally:
        monitor.destroy_node()
