"""The package's launch files (``contgrasp_ros/launch/``) and RViz configuration (``rviz/``).

The RViz configuration is checked everywhere (RViz itself needs a screen). The launch files need
``launch`` and ``launch_ros``, which every ROS 2 install has and PyPI does not: those tests run
where ``launch_ros`` imports and are skipped with that reason elsewhere (the pip-only CI).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from contgrasp_ros import topics

from conftest import fresh_domain_id

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "contgrasp_ros"


def test_the_rviz_configuration_shows_the_markers_in_their_frame() -> None:
    cfg = yaml.safe_load((PACKAGE_DIR / "rviz" / "contgrasp.rviz").read_text())
    manager = cfg["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "world"  # the frame of every marker and state
    markers = [d for d in manager["Displays"] if d["Class"] == "rviz_default_plugins/MarkerArray"]
    assert [d["Topic"]["Value"] for d in markers] == [topics.MARKERS]
    assert set(markers[0]["Namespaces"]) == {"arm", "object", "contact"}  # contgrasp_ros.markers' namespaces
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


def test_plant_launch_waits_for_a_controller(launch_ros: None) -> None:
    """The plant alone starts, and its simulator waits for the couple publisher it lacks; SIGINT
    to the launch stops every node."""
    proc = subprocess.Popen(_launch_cmd("plant.launch.py"), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=_env())
    assert proc.stdout is not None
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if "couple publishers 0/1" in line:
            break
    proc.send_signal(signal.SIGINT)
    rest, _ = proc.communicate(timeout=60)
    assert "couple publishers 0/1" in "".join(seen), "".join(seen)[-3000:] + rest[-3000:]
    assert proc.returncode == 0, rest[-3000:]
