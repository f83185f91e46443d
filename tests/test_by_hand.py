"""The graph started by hand: the four installed executables (what `ros2 run contgrasp_ros
<node>` executes: lib/contgrasp_ros/<node> under the package prefix) started one by one, with
no launcher, give the paper's settled grasp bit for bit as the launcher and the core loop do;
and a finished run stays up or exits, as ``on_finish`` says."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

from ament_index_python.packages import get_package_prefix  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from contgrasp_core.rod.session import run_sampled  # noqa: E402
from contgrasp_core.scenario import NODES, PAPER  # noqa: E402
from contgrasp_msgs.msg import RodState  # noqa: E402
from contgrasp_ros import qos, topics  # noqa: E402
from contgrasp_ros.launcher import default_params_file  # noqa: E402

from conftest import fresh_domain_id  # noqa: E402

EXE = Path(get_package_prefix("contgrasp_ros")) / "lib" / "contgrasp_ros"


class Graph:
    """Node processes on one fresh domain, and a probe node that keeps the last rod state and
    the simulator's last status."""

    def __init__(self) -> None:
        self.domain = fresh_domain_id()
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(self.domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                        PYTHONUNBUFFERED="1")
        self.procs: dict[str, subprocess.Popen[str]] = {}
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=self.domain)
        self.node = rclpy.create_node("by_hand_probe", context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.last: RodState | None = None
        self.status: dict[str, str] = {}
        self.node.create_subscription(RodState, topics.ROD_STATE, self._on_state, qos.STREAM)
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_status, qos.STREAM)

    def _on_state(self, msg: RodState) -> None:
        self.last = msg

    def _on_status(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == "rod_simulator":
                self.status = {kv.key: kv.value for kv in st.values}

    def start(self, node: str, *args: str) -> None:
        """``ros2 run contgrasp_ros NODE ARGS``: the installed executable itself."""
        self.procs[node] = subprocess.Popen([str(EXE / node), *args], env=self.env, stdout=subprocess.PIPE,
                                            stderr=subprocess.STDOUT, text=True)

    def spin_until(self, cond: Callable[[], bool], timeout: float, *, stop_on_failure: bool = True) -> bool:
        """Spin the probe until ``cond()``; False on timeout or (``stop_on_failure``) when a node
        process failed."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.05)
            if cond():
                return True
            if stop_on_failure and any(p.poll() not in (None, 0) for p in self.procs.values()):
                return cond()
        return False

    def output(self, node: str) -> str:
        proc = self.procs[node]
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
        return out

    def close(self) -> dict[str, int]:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        codes = {name: proc.wait(timeout=30) for name, proc in self.procs.items()}
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)
        return codes


@pytest.fixture
def graph():  # type: ignore[no-untyped-def]
    g = Graph()
    yield g
    for proc in g.procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    if g.ctx.ok():
        g.ex.shutdown()
        rclpy.shutdown(context=g.ctx)


@pytest.fixture(scope="module")
def paper_core() -> Any:
    """The paper scenario through the core loop alone (the reference both runs must equal)."""
    session = run_sampled(PAPER)
    return session.observe(), session


def same_as_core(state: RodState, paper_core: Any) -> None:
    obs, session = paper_core
    assert state.step == obs.k
    np.testing.assert_array_equal(state.x, obs.x[:, 0])
    np.testing.assert_array_equal(state.y, obs.x[:, 1])
    np.testing.assert_array_equal(state.theta, obs.theta)


def test_four_nodes_by_hand_without_parameters_give_the_paper_grasp_bitwise(graph: Graph, paper_core: Any) -> None:
    """No parameter file, no launcher, nodes started one after the other in any order, the
    default on_finish (idle): the run waits for its peers, settles as the paper's run does, bit
    for bit, and every node stays up afterwards and says so."""
    # (min_subscribers 3: the sensor's two rod-state subscriptions, per step and sampled, and
    # this test's probe, a participant older than the graph that Fast DDS may announce only
    # after a few seconds; step 0 waits until it hears the run)
    graph.start("rod_simulator", "--ros-args", "-p", "min_subscribers:=3")
    time.sleep(1.0)  # a person starting the next terminal
    for node in ("grasp_quality", "grasp_controller", "boundary_sensor"):
        graph.start(node)
    assert graph.spin_until(lambda: graph.status.get("state") == "finished", timeout=240), graph.status
    assert graph.spin_until(lambda: graph.last is not None and graph.last.step == int(graph.status["step"]), timeout=10)
    _, session = paper_core
    assert graph.status["missed_deadlines"] == "0" and graph.status["settled"] == "true"
    assert float(graph.status["settle_time_s"]) == session.settle_time
    assert graph.last is not None
    same_as_core(graph.last, paper_core)
    time.sleep(2.0)  # idle: nobody exits
    assert all(p.poll() is None for p in graph.procs.values()), {n: p.poll() for n, p in graph.procs.items()}
    sim_log = graph.output("rod_simulator")
    assert "waiting for the closed loop's peers before publishing step 0" in sim_log
    assert "publishing step 0" in sim_log and "staying up (on_finish: idle)" in sim_log
    assert "no couple for step" not in sim_log  # no stall, no fallback
    assert "staying up (on_finish: idle)" in graph.output("boundary_sensor")
    assert all(code == 0 for code in graph.close().values())


def test_by_hand_with_the_parameter_file_exits_when_finished_and_equals_the_launcher(
    graph: Graph, paper_core: Any, tmp_path: Path
) -> None:
    """--params-file config/default.yaml on all four and on_finish:=exit: zero missed
    deadlines, no step-0 stall, every node exits 0 by itself; the final state equals the
    launcher's run of the same file bit for bit."""
    params = str(default_params_file())
    for node in NODES:  # (the simulator waits for this test's probe too: min_subscribers, as above)
        extra = ("-p", "min_subscribers:=3") if node == "rod_simulator" else ()
        graph.start(node, "--ros-args", "--params-file", params, "-p", "on_finish:=exit", *extra)
    assert graph.spin_until(lambda: all(p.poll() is not None for p in graph.procs.values()), timeout=240), graph.status
    assert graph.status.get("state") == "finished" and graph.status["missed_deadlines"] == "0"
    assert graph.last is not None
    same_as_core(graph.last, paper_core)
    logs = {node: graph.output(node) for node in NODES}
    assert "exiting with status 0 (on_finish: exit)" in logs["rod_simulator"]
    assert "no couple for step" not in logs["rod_simulator"]
    assert all(code == 0 for code in graph.close().values())
    launched = subprocess.run([str(Path(sys.executable).parent / "contgrasp-launch"), "--json", "--no-record",
                               "--domain-id", str(fresh_domain_id()), "--params", params],
                              capture_output=True, text=True, timeout=300)
    assert launched.returncode == 0, launched.stderr[-2000:]
    out = json.loads(launched.stdout)
    assert out["final"] is not None, {k: v for k, v in out.items() if k != "history"}
    assert out["final"]["x"] == list(graph.last.x) and out["final"]["y"] == list(graph.last.y)


def test_a_failed_run_exits_1_with_on_finish_exit(graph: Graph) -> None:
    """The object overlaps the clamped base, so the first state already breaks the run: the
    simulator and a node watching it exit with status 1; with the default they stay up."""
    common = ("-p", "on_finish:=exit")
    graph.start("boundary_sensor", "--ros-args", *common)
    time.sleep(3.0)  # (up before the simulator fails)
    graph.start("rod_simulator", "--ros-args", "-p", "object_center:=[0.0, 0.0]", "-p", "wait_for_peers:=false", *common)
    assert graph.spin_until(lambda: all(p.poll() is not None for p in graph.procs.values()), timeout=60,
                            stop_on_failure=False)
    assert graph.procs["rod_simulator"].returncode == 1
    assert graph.procs["boundary_sensor"].returncode == 1
    assert "exiting with status 1 (on_finish: exit)" in graph.output("rod_simulator")
    assert "the simulator's run failed" in graph.output("boundary_sensor")


def test_the_container_hosts_the_sensor_and_controller_by_hand(graph: Graph, paper_core: Any) -> None:
    """``ros2 run contgrasp_ros container boundary_sensor grasp_controller`` beside the
    simulator: each node reads its own section of the parameter file, the run is the paper's
    grasp bit for bit, and the container exits 0 once both of its nodes are done."""
    params = str(default_params_file())
    graph.start("rod_simulator", "--ros-args", "--params-file", params, "-p", "on_finish:=exit", "-p", "min_subscribers:=3")
    graph.start("container", "boundary_sensor", "grasp_controller", "--ros-args", "--params-file", params,
                "-p", "on_finish:=exit")
    assert graph.spin_until(lambda: all(p.poll() is not None for p in graph.procs.values()), timeout=240), graph.status
    assert graph.status.get("state") == "finished" and graph.status["missed_deadlines"] == "0"
    assert graph.last is not None
    same_as_core(graph.last, paper_core)
    log = graph.output("container")
    assert "[boundary_sensor]" in log and "[grasp_controller]" in log and "exiting with status 0" in log
    assert all(code == 0 for code in graph.close().values())


@pytest.mark.parametrize(("args", "needle"), [
    ([], "name the nodes"),
    (["boundary_sensor", "planner"], "unknown node(s) planner"),
    (["grasp_controller", "grasp_controller"], "at most once"),
    (["boundary_sensor", "grasp_controller", "--ros-args", "-p", "mu1:=0.0"], "GraspController: error: invalid parameter"),
])
def test_the_container_refuses_bad_usage_with_exit_2(args: list[str], needle: str) -> None:
    env = dict(os.environ, ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.run([str(EXE / "container"), *args], capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 2 and needle in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]


def test_the_container_help() -> None:
    proc = subprocess.run([str(EXE / "container"), "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.startswith("usage: container NODE") and "grasp_quality" in proc.stdout
