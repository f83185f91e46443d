"""The package's launch files (``contgrasp_ros/launch/``) and RViz configuration (``rviz/``).

The RViz configuration is checked everywhere (RViz itself needs a screen). The launch files need
``launch`` and ``launch_ros``, which every ROS 2 install has and PyPI does not: those tests run
where ``launch_ros`` imports and are skipped with that reason elsewhere (the pip-only CI).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from contgrasp_ros.plumbing import topics

from conftest import fresh_domain_id

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "contgrasp_ros"


def test_the_rviz_configuration_shows_the_markers_in_their_frame() -> None:
    cfg = yaml.safe_load((PACKAGE_DIR / "rviz" / "contgrasp.rviz").read_text())
    manager = cfg["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "world"  # the frame of every marker and state
    markers = [d for d in manager["Displays"] if d["Class"] == "rviz_default_plugins/MarkerArray"]
    # (relative, as the graph's names are: RViz resolves it under its own namespace, the graph's)
    assert [d["Topic"]["Value"] for d in markers] == [topics.MARKERS]
    assert topics.resolve(markers[0]["Topic"]["Value"]) == "/contgrasp/markers"
    assert topics.resolve(markers[0]["Topic"]["Value"], "/r1") == "/r1/contgrasp/markers"
    assert set(markers[0]["Namespaces"]) == {"arm", "object", "contact"}  # contgrasp_ros.plumbing.markers' namespaces
    assert manager["Views"]["Current"]["Class"] == "rviz_default_plugins/TopDownOrtho"  # the grasp's plane


def _launch_cmd(file: str, *args: str) -> list[str]:
    """``ros2 launch contgrasp_ros FILE ARGS`` through the launch API (ros2cli may be absent)."""
    code = ("import sys; from launch import LaunchDescription, LaunchService; "
            "from launch.actions import IncludeLaunchDescription; "
            "from launch.launch_description_sources import PythonLaunchDescriptionSource; "
            "ls = LaunchService(argv=sys.argv[2:]); "
            "ls.include_launch_description(IncludeLaunchDescription(PythonLaunchDescriptionSource(sys.argv[1]), "
            "launch_arguments=[a.split(':=', 1) for a in sys.argv[2:]])); sys.exit(ls.run())")
    return [sys.executable, "-c", code, str(PACKAGE_DIR / "launch" / file), *args]


def _env() -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")


@pytest.fixture(scope="module")
def launch_ros() -> None:
    pytest.importorskip("launch_ros", reason="launch_ros is part of a ROS 2 install, not a wheel (docs/ros.md, "
                                             "'In a ROS 2 workspace')")


# Evaluates a launch file as `ros2 launch` would, without starting a process: each node's
# package, executable and the namespace and remapping rules in force where it is launched, as JSON.
_LAUNCH_NODES = """
import json, sys
from launch import LaunchContext
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.utilities import normalize_to_list_of_substitutions, perform_substitutions
from launch_ros.actions import Node

context = LaunchContext()
context.launch_configurations.update(a.split(":=", 1) for a in sys.argv[2:])
description = PythonLaunchDescriptionSource(sys.argv[1]).get_launch_description(context)


def text(value):
    return perform_substitutions(context, normalize_to_list_of_substitutions(value))


def nodes(entities):
    for entity in entities:
        if entity.condition is not None and not entity.condition.evaluate(context):
            continue
        if isinstance(entity, Node):
            yield {"package": text(entity.node_package), "executable": text(entity.node_executable),
                   "namespace": context.launch_configurations.get("ros_namespace", "/"),
                   "remaps": [list(rule) for rule in context.launch_configurations.get("ros_remaps", [])]}
        else:
            yield from nodes(entity.visit(context) or [])


print(json.dumps(list(nodes(description.entities))))
"""


@pytest.mark.parametrize("namespace", ["", "arm1"])
def test_rviz_runs_in_the_graphs_namespace(launch_ros: None, tmp_path: Path, namespace: str) -> None:
    """``rviz:=true`` starts RViz where the graph's nodes are: under ``namespace:=arm1`` it
    resolves its configuration's relative ``contgrasp/markers`` to ``/arm1/contgrasp/markers``,
    which the simulator there publishes (RViz was outside the group, on ``/contgrasp/markers``,
    which a namespaced graph does not publish)."""
    args = ["rviz:=true", *([f"namespace:={namespace}"] if namespace else [])]
    # (the description only, nothing runs: an ament index entry stands in for RViz where it is not
    # installed, which the launch file checks for)
    marker = tmp_path / "prefix" / "share" / "ament_index" / "resource_index" / "packages" / "rviz2"
    marker.parent.mkdir(parents=True)
    marker.touch()
    env = dict(_env(), ROS_LOG_DIR=str(tmp_path), AMENT_PREFIX_PATH=os.pathsep.join(
        [os.environ.get("AMENT_PREFIX_PATH", ""), str(tmp_path / "prefix")]).lstrip(os.pathsep))
    out = subprocess.run([sys.executable, "-c", _LAUNCH_NODES, str(PACKAGE_DIR / "launch" / "paper_grasp.launch.py"), *args],
                         env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    nodes = {node["executable"]: node for node in json.loads(out.stdout)}
    assert sorted(nodes) == ["boundary_sensor", "grasp_controller", "grasp_quality", "rod_simulator", "rviz2"]
    rviz, simulator = nodes["rviz2"], nodes["rod_simulator"]
    assert rviz["package"] == "rviz2"
    assert rviz["namespace"] == simulator["namespace"] == ("/" + namespace if namespace else "/")
    assert rviz["remaps"] == simulator["remaps"]  # (the namespace's clock, when one is given)
    cfg = yaml.safe_load((PACKAGE_DIR / "rviz" / "contgrasp.rviz").read_text())
    topic = next(d["Topic"]["Value"] for d in cfg["Visualization Manager"]["Displays"]
                 if d["Class"] == "rviz_default_plugins/MarkerArray")
    assert topics.resolve(topic, rviz["namespace"]) == topics.resolve(topics.MARKERS, simulator["namespace"])


def test_rviz_without_rviz2_is_refused_before_any_node(launch_ros: None, tmp_path: Path) -> None:
    """``rviz:=true`` where RViz 2 is not installed: refused with what to install before any node
    is described (launch used to start the nodes, fail on RViz and leave them running)."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        get_package_prefix("rviz2")
        pytest.skip("RViz 2 is installed here")
    except PackageNotFoundError:
        pass
    out = subprocess.run([sys.executable, "-c", _LAUNCH_NODES, str(PACKAGE_DIR / "launch" / "paper_grasp.launch.py"), "rviz:=true"],
                         env=dict(_env(), ROS_LOG_DIR=str(tmp_path)), capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and out.stdout == ""
    assert out.stderr.strip().splitlines()[-1].endswith(
        "rviz:=true needs RViz 2, the package rviz2 (apt install ros-jazzy-rviz2), which is not installed: launch with rviz:=false")


def test_paper_grasp_launch_runs_the_paper_grasp(launch_ros: None) -> None:
    from contgrasp_core.rod.session import run_sampled
    from contgrasp_core.scenario import PAPER

    out = subprocess.run(_launch_cmd("paper_grasp.launch.py", "on_finish:=exit"), capture_output=True, text=True,
                         timeout=300, env=_env())
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    log = out.stdout + out.stderr
    settle = run_sampled(PAPER).settle_time
    assert f"(settled at {settle:.3f} s, missed deadlines: 0)" in log, log[-3000:]
    assert "no couple for step" not in log


def test_plant_launch_waits_for_a_controller_started_later(launch_ros: None) -> None:
    """The plant alone (wall clock) waits for the couple publisher it lacks; a controller started
    by hand afterwards closes the loop, and the run finishes (seen broken with the real tools: step
    0 went out at once and the late controller never saw a contact state)."""
    from ament_index_python.packages import get_package_prefix

    env = _env()
    proc = subprocess.Popen(_launch_cmd("plant.launch.py", "duration:=0.3", "on_finish:=exit"), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env)
    controller = None
    assert proc.stdout is not None
    seen = []
    try:
        for line in proc.stdout:
            seen.append(line)
            if "couple publishers 0/1" in line and controller is None:
                exe = Path(get_package_prefix("contgrasp_ros")) / "lib" / "contgrasp_ros" / "grasp_controller"
                controller = subprocess.Popen([str(exe), "--ros-args", "-p", "on_finish:=exit"], env=env,
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        proc.wait(timeout=120)
        assert controller is not None and controller.wait(timeout=60) == 0
    finally:
        for p in (proc, controller):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGINT)
                p.wait(timeout=60)
    log = "".join(seen)
    assert proc.returncode == 0, log[-3000:]
    assert "publishing step 0" in log and "couple publishers 1/1" in log, log[-3000:]
    assert "finished at t = 0.3" in log and "free-running without one" not in log, log[-3000:]


def _end(pids: list[int]) -> None:
    """End the node processes a launch started (by pid: a launch stopped with SIGTERM leaves them
    running, launch's documented limit), SIGINT first, SIGKILL after 20 s."""
    for sig in (signal.SIGINT, signal.SIGKILL):
        for pid in pids:
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        end = time.monotonic() + 20
        while time.monotonic() < end and any(Path(f"/proc/{pid}").exists() for pid in pids):
            time.sleep(0.1)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stopped_launch_leaves_no_temporary_files(launch_ros: None, tmp_path: Path, sig: signal.Signals) -> None:
    """Stopped while the simulator waits for a controller, ros2 launch leaves nothing in the
    temporary folder (launch's SIGTERM skips the shutdown event, so a clean-up on it never ran
    there): the nodes' overrides are a file in the launch's log folder."""
    tmp, logs = tmp_path / "tmp", tmp_path / "log"
    tmp.mkdir()
    env = dict(_env(), TMPDIR=str(tmp), ROS_LOG_DIR=str(logs))
    proc = subprocess.Popen(_launch_cmd("plant.launch.py"), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env)
    assert proc.stdout is not None
    pids: list[int] = []
    seen = []
    try:
        for line in proc.stdout:
            seen.append(line)
            pids += [int(pid) for pid in re.findall(r"process started with pid \[(\d+)\]", line)]
            if "couple publishers 0/1" in line:  # every node started, the simulator waiting
                break
        proc.send_signal(sig)
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _end(pids)
    assert len(pids) == 3, "".join(seen)[-3000:]
    assert list(tmp.iterdir()) == []
    overrides = list({path.resolve() for path in logs.glob("*/contgrasp_overrides_*.yaml")})  # (log/latest links)
    assert len(overrides) == 1 and yaml.safe_load(overrides[0].read_text())["rod_simulator"]["ros__parameters"]["lockstep"] is False
