"""The graph as ROS 2 launch entities, for ``launch/paper_grasp.launch.py`` and ``launch/plant.launch.py``.

The nodes, their executables and parameters come from :mod:`contgrasp_ros.launcher.graph`, as those of
``contgrasp-launch`` do. Needs ``launch`` and ``launch_ros`` (part of every ROS 2 install; not
published as wheels, so the pip-only set-up has no ``ros2 launch``; docs/ros.md, "In a ROS 2
workspace").
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch.conditions import IfCondition
from launch.logging import launch_config
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node, PushRosNamespace, SetRemap
from launch_ros.substitutions import FindPackageShare

from contgrasp_core.control.hold_law import LAWS
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.objects import ROD_SCALE, ObjectSpec
from contgrasp_core.rod.body import MODES
from contgrasp_core.scenario import SIMULATOR
from contgrasp_ros.launcher.graph import (
    COMPOSABLE,
    PACKAGE,
    RECORDER,
    compose_groups,
    launch_overrides,
    load_params,
    parameter_file,
    processes,
    recorder_params,
)
from contgrasp_ros.plumbing import topics

__all__ = ["graph_description"]


def _arguments(lockstep: bool) -> list[DeclareLaunchArgument]:
    return [
        DeclareLaunchArgument("params_file", default_value=PathJoinSubstitution([FindPackageShare(PACKAGE), "config", "default.yaml"]),
                              description="ROS 2 parameter file of the scenario (default: the installed package's "
                                          "share/contgrasp_ros/config/default.yaml, the paper's)"),
        DeclareLaunchArgument("object", default_value="",
                              description="built-in object NAME[:PARAMS] in metres: circle[:R], ellipse[:a,b], "
                                          "deformed[:R,amplitude,lobes,phase] (default: the parameter file's)"),
        DeclareLaunchArgument("outline", default_value="", description="your own object: a CSV outline, rows x, y in metres"),
        DeclareLaunchArgument("law", default_value="", choices=["", *LAWS],
                              description="the controller's law: paper (eq. (19)), hold (the planned hold) or reactive (docs/holding.md) "
                                          "(default: the parameter file's)"),
        DeclareLaunchArgument("object_mode", default_value="", choices=["", *MODES],
                              description="how the object moves: fixed (the paper), spring or free (default: the parameter file's)"),
        DeclareLaunchArgument("max_muscle_stress", default_value="",
                              description="the muscles' largest stress [Pa]: bounds each section's couple; 0: unbounded "
                                          "(default: the parameter file's)"),
        DeclareLaunchArgument("friction", default_value="",
                              description="Coulomb friction coefficient of the contact, stick-slip when > 0; 0: "
                                          "frictionless (default: the parameter file's)"),
        DeclareLaunchArgument("lockstep", default_value=str(lockstep).lower(), choices=["true", "false"],
                              description="true: lock-step simulated time, deterministic; false: the wall clock (real time)"),
        DeclareLaunchArgument("duration", default_value="", description="simulated seconds at most (default: the parameter file's)"),
        DeclareLaunchArgument("compose", default_value="false", choices=["true", "false"],
                              description=f"host {', '.join(COMPOSABLE)} (those launched) in one process"),
        DeclareLaunchArgument("record", default_value="false", choices=["true", "false"],
                              description="record the run to MCAP with the mcap_recorder node"),
        DeclareLaunchArgument("bag", default_value="", description="record: the bag folder (default bags/run_<date>_<time>)"),
        DeclareLaunchArgument("on_finish", default_value="idle", choices=["idle", "exit"],
                              description="when the run is over: every node stays up (idle) or exits (exit), ending the launch"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="run the graph under this ROS namespace, with its own clock <namespace>/clock "
                                          "(e.g. two arms in one domain; default: none)"),
        DeclareLaunchArgument("rviz", default_value="false", choices=["true", "false"],
                              description="open RViz with the package's rviz/contgrasp.rviz"),
    ]


def _number(name: str, text: str) -> float | None:
    """A launch argument's number (None when not given)."""
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        raise InvalidParameterError(f"{name}:={text!r} is not a number") from None


def _nodes(context: LaunchContext, nodes: Sequence[str]) -> list[GroupAction | Node]:
    """The graph's node processes with the launch arguments applied (the launcher's rules: an
    override file after the scenario's parameter file, kept in the launch's log folder), and RViz
    on ``rviz:=true``, in a group under ``namespace`` when given (``PushRosNamespace``, and
    ``/clock`` remapped to the namespace's clock on every node of the group)."""
    arg = {name: LaunchConfiguration(name).perform(context) for name in
           ("params_file", "object", "outline", "law", "object_mode", "max_muscle_stress", "friction", "lockstep", "duration", "compose",
            "record", "bag", "on_finish", "namespace", "rviz")}
    if arg["rviz"] == "true":
        _require_rviz()
    params_file = Path(arg["params_file"])
    params = load_params(params_file)
    record = arg["record"] == "true"
    # (each node's whole scenario too: the parameter file's ``node:`` sections name the node at the root only)
    overrides: dict[str, dict[str, Any]] = {name: {**params[name], "use_sim_time": True, "on_finish": arg["on_finish"]}
                                            for name in nodes}
    obj = ObjectSpec.from_cli(arg["object"] or None, arg["outline"] or None, ROD_SCALE) if arg["object"] or arg["outline"] else None
    for name, values in launch_overrides(params, obj, arg["law"] or None, arg["object_mode"] or None,
                                         _number("max_muscle_stress", arg["max_muscle_stress"]),
                                         _number("friction", arg["friction"])).items():
        if name in overrides:
            overrides[name].update(values)
    sim = overrides[SIMULATOR]
    sim["lockstep"] = arg["lockstep"] == "true"
    if arg["duration"]:
        try:
            sim["duration"] = float(arg["duration"])
        except ValueError:
            raise InvalidParameterError(f"duration:={arg['duration']!r} is not a number of seconds") from None
    if record:
        sim["min_subscribers"] = 2  # the sensor and the recorder hear the first state
        from contgrasp_ros.nodes.mcap_recorder import default_output

        overrides[RECORDER] = {**recorder_params({"output": arg["bag"] or default_output()}), "on_finish": arg["on_finish"]}
    compose = compose_groups([",".join(n for n in COMPOSABLE if n in nodes)], nodes) if arg["compose"] == "true" else []
    override_file = parameter_file(_override_path(), overrides, arg["namespace"])
    graph: list[GroupAction | Node] = [
        # (sigterm_timeout: a node's clean-up takes seconds on a busy machine, the recorder's
        # finalises the bag; launch's 5 s default then escalated to SIGTERM)
        Node(package=PACKAGE, executable=proc.executable, arguments=list(proc.arguments), output="screen",
             parameters=[str(override_file)] if proc.name == RECORDER else [str(params_file), str(override_file)],
             sigterm_timeout="20")
        for proc in processes(nodes, compose, record=record)
    ]
    # RViz in the group too: its configuration names the markers relatively (``contgrasp/markers``),
    # so under the namespace it shows this graph's ``<namespace>/contgrasp/markers``
    rviz_config = PathJoinSubstitution([FindPackageShare(PACKAGE), "rviz", "contgrasp.rviz"])
    graph.append(Node(package="rviz2", executable="rviz2", arguments=["-d", rviz_config], output="screen",
                      condition=IfCondition(LaunchConfiguration("rviz"))))
    if not arg["namespace"].strip("/"):
        return graph
    return [GroupAction([PushRosNamespace(arg["namespace"]), SetRemap(topics.CLOCK, topics.namespace_clock(arg["namespace"])), *graph])]


def _require_rviz() -> None:
    """``rviz:=true`` needs RViz 2 (a desktop install's ``rviz2``): refused before any node starts,
    where ``launch`` would start the nodes, then fail on RViz and leave them running."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        get_package_prefix("rviz2")
    except PackageNotFoundError:
        raise InvalidParameterError("rviz:=true needs RViz 2, the package rviz2 (apt install ros-jazzy-rviz2), "
                                    "which is not installed: launch with rviz:=false") from None


def _override_path() -> Path:
    """A new file for the launch's overrides in the launch's own log folder (beside its
    ``launch.log``; ``ROS_LOG_DIR``, by default ``~/.ros/log/<date>-<host>-<pid>/``): a record of
    what the nodes were given, and no temporary file to remove, since no way out of ``ros2
    launch`` (SIGTERM skips the shutdown event) could leave one behind."""
    fd, name = tempfile.mkstemp(prefix="contgrasp_overrides_", suffix=".yaml", dir=launch_config.log_dir)
    os.close(fd)
    return Path(name)


def graph_description(nodes: Sequence[str], *, lockstep: bool) -> LaunchDescription:
    """The launch description of a graph of ``nodes`` (:data:`contgrasp_ros.launcher.graph.LOOP` or
    :data:`~contgrasp_ros.launcher.graph.PLANT`), lock-step by default when ``lockstep``, with RViz on
    ``rviz:=true``."""
    return LaunchDescription([
        *_arguments(lockstep),
        OpaqueFunction(function=_nodes, args=[tuple(nodes)]),
    ])
