"""The repository as a ROS 2 user builds it: under ``src/`` of a workspace, ``colcon build`` on
top of this venv (its pinned ROS 2 Jazzy wheels are the underlay, as /opt/ros/jazzy would be),
``source install/setup.bash``, then the four graph nodes started from ``install/`` by hand
(what ``ros2 run contgrasp_ros <node>`` executes) give the paper's grasp bit for bit as the core
loop does (docs/ros.md, "In a ROS 2 workspace")."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

pytestmark = pytest.mark.heavy(per_module=True)  # (its tests share one colcon workspace build: one shard builds it)

pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")
if shutil.which("colcon", path=os.pathsep.join([str(Path(sys.prefix) / "bin"), os.environ.get("PATH", "")])) is None:
    pytest.skip("colcon is not installed (the set-up's test extra installs colcon-common-extensions)", allow_module_level=True)

import test_by_hand as by_hand  # noqa: E402 - the by-hand graph and its fixtures
from conftest import domain_class, fresh_domain_id  # noqa: E402

Graph = by_hand.Graph
graph = by_hand.graph
paper_core = by_hand.paper_core

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ("rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality", "mcap_recorder", "foxglove_bridge",
            "container")


def _underlay_env() -> dict[str, str]:
    """This venv as the ROS underlay, activated: its interpreter first on PATH, its prefix in the
    ament and CMake search paths."""
    venv = Path(sys.prefix)
    return dict(os.environ, VIRTUAL_ENV=str(venv), PATH=os.pathsep.join([str(venv / "bin"), os.environ.get("PATH", "")]),
                AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv), PYTHONUNBUFFERED="1")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A workspace holding this checkout's files under src/contgrasp, built with colcon; the
    environment ``source install/setup.bash`` gives."""
    ws = tmp_path_factory.mktemp("ws")
    names = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in (n for n in names if n and (ROOT / n).is_file()):
        (ws / "src" / "contgrasp" / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, ws / "src" / "contgrasp" / name)
    env = _underlay_env()
    listed = subprocess.run(["colcon", "list", "--names-only"], cwd=ws, env=env, capture_output=True, text=True, check=True)
    build = subprocess.run(["colcon", "build", "--event-handlers", "console_direct-"],
                           cwd=ws, env=env, capture_output=True, text=True, timeout=900)
    assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-4000:]
    sourced = subprocess.run(["bash", "-c", "source install/setup.bash && env -0"], cwd=ws, env=env, capture_output=True,
                             check=True).stdout.decode()
    return {"ws": ws, "packages": listed.stdout.split(), "build": build.stdout,
            "env": dict(line.split("=", 1) for line in sourced.split("\0") if "=" in line)}


def test_colcon_builds_both_packages_and_installs_what_a_ros_package_installs(workspace: dict[str, Any]) -> None:
    assert sorted(workspace["packages"]) == ["contgrasp_msgs", "contgrasp_ros"]
    prefix = workspace["ws"] / "install" / "contgrasp_ros"
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "contgrasp_ros").is_file()
    share = prefix / "share" / "contgrasp_ros"
    for name in ("package.xml", "config/default.yaml", "launch/paper_grasp.launch.py", "launch/plant.launch.py",
                 "rviz/contgrasp.rviz"):
        assert (share / name).is_file(), name
    for program in PROGRAMS:
        assert os.access(prefix / "lib" / "contgrasp_ros" / program, os.X_OK), program
    where = subprocess.run(["python3", "-c", "import contgrasp_core, contgrasp_msgs, contgrasp_ros; "
                            "print(contgrasp_core.__file__, contgrasp_ros.__file__, contgrasp_msgs.__file__)"],
                           env=workspace["env"], cwd=workspace["ws"], capture_output=True, text=True, check=True).stdout.split()
    assert all(path.startswith(str(workspace["ws"] / "install")) for path in where), where


def test_colcon_test_runs_the_node_tests_and_they_pass(workspace: dict[str, Any]) -> None:
    """`colcon test` runs the package's node tests (CMakeLists.txt, ament_cmake_pytest) against the
    install; `colcon test-result` counts them: some, none failed."""
    env = dict(workspace["env"], ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               **domain_class())  # (its domains this worker's, never those of CI's other leg running at once)
    env.pop("CONTGRASP_TEST_SHARD", None)  # (the node tests run whole under colcon, whatever CI's shard)
    test = subprocess.run(["colcon", "test", "--packages-select", "contgrasp_ros", "--event-handlers", "console_direct-"],
                          cwd=workspace["ws"], env=env, capture_output=True, text=True, timeout=900)
    assert test.returncode == 0, test.stdout[-4000:] + test.stderr[-4000:]
    result = subprocess.run(["colcon", "test-result", "--all", "--verbose", "--test-result-base", "build/contgrasp_ros"],
                            cwd=workspace["ws"], env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    counts = r"(\d+) tests, (\d+) errors, (\d+) failures, \d+ skipped"
    files = {name: tuple(map(int, n)) for name, *n in re.findall(r"contgrasp_ros/(test_\w+)\.xunit\.xml: " + counts, result.stdout)}
    assert sorted(files) == ["test_cdr", "test_lockstep", "test_ros_nodes"], result.stdout
    assert all(tests > 0 and errors == failures == 0 for tests, errors, failures in files.values()), result.stdout
    summary = re.search("Summary: " + counts, result.stdout)
    assert summary is not None and int(summary[1]) >= sum(t for t, _, _ in files.values()) > 0, result.stdout


def test_the_executables_run_the_python_of_the_build_whatever_python3_is_first_on_path(workspace: dict[str, Any],
                                                                                      tmp_path: Path) -> None:
    """Each installed executable starts with a #! of the build's interpreter (this venv's), as
    ament_python's scripts do: a python3 first on PATH without the layer does not run it."""
    exe = workspace["ws"] / "install" / "contgrasp_ros" / "lib" / "contgrasp_ros"
    for program in PROGRAMS:
        shebang = (exe / program).read_text().splitlines()[0]
        assert Path(shebang.removeprefix("#!")).parent == Path(sys.prefix) / "bin", (program, shebang)
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "python3").write_text(f"#!/bin/sh\necho ran > {tmp_path / 'fake_ran'}\nexit 1\n")
    (fake / "python3").chmod(0o755)
    env = dict(workspace["env"], PATH=os.pathsep.join([str(fake), workspace["env"]["PATH"]]))
    out = subprocess.run([str(exe / "container"), "--help"], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.startswith("usage: container NODE"), out.stdout + out.stderr
    assert not (tmp_path / "fake_ran").exists()


# Evaluates an installed launch file as `ros2 launch` would, without starting a process: prints
# each node's command line (executable, then its arguments with the parameter files) as JSON.
_LAUNCH_COMMANDS = """
import json, sys
from launch import LaunchContext
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.utilities import perform_substitutions
from launch_ros.actions import Node

context = LaunchContext()
context.launch_configurations.update(a.split(":=", 1) for a in sys.argv[2:])
description = PythonLaunchDescriptionSource(sys.argv[1]).get_launch_description(context)


def nodes(entities):
    for entity in entities:
        if entity.condition is not None and not entity.condition.evaluate(context):
            continue
        if isinstance(entity, Node):
            entity._perform_substitutions(context)
            yield [perform_substitutions(context, part) for part in entity.cmd]
        else:
            yield from nodes(entity.visit(context) or [])


print(json.dumps(list(nodes(description.entities))))
"""


def _launch_commands(workspace: dict[str, Any], log_dir: Path, file: str, *args: str) -> dict[str, list[str]]:
    """The node processes the installed launch ``file`` starts with ``args``: executable name ->
    command line (the launch's log folder, where its override file goes, under ``log_dir``)."""
    launch = workspace["ws"] / "install" / "contgrasp_ros" / "share" / "contgrasp_ros" / "launch" / file
    out = subprocess.run(["python3", "-c", _LAUNCH_COMMANDS, str(launch), *args], env=dict(workspace["env"], ROS_LOG_DIR=str(log_dir)),
                         cwd=workspace["ws"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    return {Path(cmd[0]).name: cmd for cmd in json.loads(out.stdout)}


def _params_files(cmd: list[str]) -> list[Path]:
    return [Path(cmd[i + 1]) for i, arg in enumerate(cmd) if arg == "--params-file"]


def test_the_launch_files_read_the_installed_share_configuration(workspace: dict[str, Any], tmp_path: Path) -> None:
    """The default parameter file is share/contgrasp_ros/config/default.yaml of the install (the
    ament index's), not the copy among the Python files; an edit of it is what the nodes get."""
    pytest.importorskip("launch_ros", reason="launch_ros is part of a ROS 2 install, not a wheel (docs/ros.md)")
    share = workspace["ws"] / "install" / "contgrasp_ros" / "share" / "contgrasp_ros" / "config" / "default.yaml"
    commands = _launch_commands(workspace, tmp_path, "paper_grasp.launch.py")
    assert sorted(commands) == ["boundary_sensor", "grasp_controller", "grasp_quality", "rod_simulator"]
    for cmd in commands.values():
        assert _params_files(cmd)[0] == share, cmd
    original = share.read_text()
    try:
        share.write_text(original.replace("    duration: 4.0 ", "    duration: 1.25 "))
        cmd = _launch_commands(workspace, tmp_path, "paper_grasp.launch.py", "object:=ellipse")["rod_simulator"]
    finally:
        share.write_text(original)
    files = _params_files(cmd)
    # (the object's override is the scenario of the parameter file with the object changed)
    overrides = yaml.safe_load(files[1].read_text())
    assert files[0] == share and overrides["rod_simulator"]["ros__parameters"]["duration"] == 1.25


def test_the_nodes_from_install_give_the_paper_grasp_bitwise(workspace: dict[str, Any], graph: Graph, paper_core: Any) -> None:
    """The four nodes started by hand from the workspace's install/ (no parameter file, no
    launcher) settle as the core loop does, bit for bit."""
    graph.env = dict(workspace["env"], ROS_DOMAIN_ID=str(graph.domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    exe = workspace["ws"] / "install" / "contgrasp_ros" / "lib" / "contgrasp_ros"
    for node in ("rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality"):
        # (min_subscribers 3: the sensor's two rod-state subscriptions and this test's probe)
        extra = ["-p", "min_subscribers:=3"] if node == "rod_simulator" else []
        # (in the workspace, as a user would be: python -m puts the working directory first on sys.path)
        graph.procs[node] = subprocess.Popen([str(exe / node), "--ros-args", "-p", "on_finish:=exit", *extra], env=graph.env,
                                             cwd=workspace["ws"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        time.sleep(0.5)
    assert graph.spin_until(lambda: graph.status.get("state") == "finished", timeout=240), graph.status
    assert graph.spin_until(lambda: graph.last is not None and graph.last.step == int(graph.status["step"]), timeout=10)
    _, session = paper_core
    assert graph.status["missed_deadlines"] == "0" and float(graph.status["settle_time_s"]) == session.settle_time
    assert graph.last is not None
    by_hand.same_as_core(graph.last, paper_core)
    # on_finish:=exit: every node ends by itself, a grace second after it hears of the end (the
    # probe may hear it first: a Ctrl-C from here now would stop the controller before it does)
    codes = {name: proc.wait(timeout=30) for name, proc in graph.procs.items()}
    assert codes == dict.fromkeys(graph.procs, 0), codes
    obs, _ = paper_core  # (the time as the simulator words it: 4 digits, not the status text's 17)
    assert f"the simulator's run finished at t = {obs.t:.4g} s; exiting" in graph.output("grasp_controller")
    graph.close()
