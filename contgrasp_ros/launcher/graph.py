"""The graph's one description: which node processes run, what each executes, and their parameters.

``contgrasp-launch`` (:mod:`contgrasp_ros.launcher.graph_run`) and the launch files
(``launch/paper_grasp.launch.py``, ``launch/plant.launch.py``) both build their processes from
:func:`processes` and their parameter files from :func:`load_params`, :func:`object_parameters`
and :func:`recorder_params`, so there is no second list of nodes and parameters to drift.
No rclpy here: the launch files are loaded by ``ros2 launch`` before any node exists.
"""

from __future__ import annotations

import json
from difflib import get_close_matches
from functools import cache
from collections.abc import Sequence
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.objects import ObjectSpec
from contgrasp_core.scenario import CONTROLLER, NODES, QUALITY, SIMULATOR, Scenario
from contgrasp_ros.plumbing import topics
from contgrasp_ros.launcher.supervision import RECORDER

__all__ = ["PACKAGE", "RECORDER", "CONTAINER", "LOOP", "PLANT", "COMPOSABLE", "DECIMATED_STREAMS", "Process",
           "compose_groups", "processes", "default_params_file", "load_params", "object_parameters", "launch_overrides",
           "recorder_params",
           "parameter_file"]

PACKAGE = "contgrasp_ros"
CONTAINER = "container"
LOOP = NODES
"""The closed loop: simulator, boundary sensor, controller, quality evaluator (in start order)."""
PLANT = (SIMULATOR, "boundary_sensor", QUALITY)
"""The plant without the paper's controller, for a user's own (``plant.launch.py``)."""
COMPOSABLE = ("boundary_sensor", CONTROLLER, QUALITY)
"""The nodes one container process may host (the simulator always runs alone)."""
DECIMATED_STREAMS = (topics.ROD_STATE, topics.CONTACT, topics.COUPLE)
"""The bulky per-step topics a recording may decimate (``--bag-decimate``)."""


@dataclass(frozen=True)
class Process:
    """One node process: ``executable`` in ``lib/contgrasp_ros/`` (what ``ros2 run`` runs; also
    ``python -m contgrasp_ros.entry EXECUTABLE``) with ``arguments`` before ``--ros-args``;
    ``name`` labels it (a container's is its nodes joined by ``+``)."""

    name: str
    executable: str
    arguments: tuple[str, ...] = ()


def compose_groups(texts: Sequence[str], nodes: Sequence[str] = LOOP) -> list[tuple[str, ...]]:
    """The container groups named by ``texts`` (``"boundary_sensor,grasp_controller"`` each),
    checked: two or more of :data:`COMPOSABLE` among ``nodes`` per group, each node in one group
    at most. The error names the offending group."""
    allowed = [n for n in COMPOSABLE if n in nodes]
    groups: list[tuple[str, ...]] = []
    seen: set[str] = set()
    for text in texts:
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        if len(names) < 2 or any(n not in allowed for n in names) or len(set(names)) != len(names) or seen & set(names):
            raise InvalidParameterError(f"compose group {text!r}: give two or more of {', '.join(allowed)}, comma-separated, "
                                        "each node in one group at most (the simulator always runs alone)")
        seen.update(names)
        groups.append(names)
    return groups


def processes(nodes: Sequence[str] = LOOP, compose: Sequence[tuple[str, ...]] = (), record: bool = False) -> list[Process]:
    """The node processes of a graph of ``nodes``, in start order: the recorder first when
    ``record`` (it must hear the first state), then each node alone, except that each group of
    ``compose`` (:func:`compose_groups`) runs as one container process, started where its first
    node would be."""
    hosts = {name: group for group in compose for name in group}
    out = [Process(RECORDER, RECORDER)] if record else []
    for name in nodes:
        group = hosts.get(name)
        if group is None:
            out.append(Process(name, name))
        elif name == group[0]:
            out.append(Process("+".join(group), CONTAINER, group))
    return out


def default_params_file() -> Path:
    """The packaged default parameter file (the paper's scenario)."""
    return Path(str(resources.files(PACKAGE) / "config" / "default.yaml"))


RUNTIME_PARAMETERS = ("use_sim_time", "start_type_description_service", "on_finish", "finish_ack_timeout",
                      "max_future_stamp")
"""Parameters every node of the loop declares beyond the packaged file's (rclpy's and the node runtime's)."""
NODE_PARAMETERS = {SIMULATOR: ("start_paused", "wait_for_peers", "peer_timeout", "min_subscribers", "max_kinetic_energy",
                               "max_penetration_limit")}
"""Parameters a node declares beyond the packaged file's and :data:`RUNTIME_PARAMETERS` (tests/test_scenario.py
checks these lists against what each node declares)."""


def known_parameters(node: str) -> set[str]:
    """The parameters ``node`` takes: the packaged file's (``/**`` included), the runtime's and its own."""
    defaults = _packaged()
    return {*defaults["/**"], *defaults[node], *RUNTIME_PARAMETERS, *NODE_PARAMETERS.get(node, ())}


@cache
def _packaged() -> dict[str, dict[str, Any]]:
    """The packaged file's sections (read once; never changed)."""
    return _sections(default_params_file())


def _sections(path: Path) -> dict[str, dict[str, Any]]:
    """The sections of a ROS 2 YAML parameter file, ``/**`` and each node's (its leading ``/``
    dropped), each its ``ros__parameters``."""
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise InvalidParameterError(f"cannot read parameter file {path}: {exc}") from exc
    if not isinstance(data, dict):
        raise InvalidParameterError(f"{path} is not a ROS 2 parameter file (expected a mapping)")
    out: dict[str, dict[str, Any]] = {"/**": {}}
    for name, section in data.items():
        section = section or {}
        values = section.get("ros__parameters", {}) if isinstance(section, dict) else None
        if not isinstance(values, dict):
            raise InvalidParameterError(f"{path} is not a ROS 2 parameter file (node sections need 'ros__parameters' mappings)")
        out[name if name == "/**" else str(name).lstrip("/")] = values
    return out


def _check_known(path: Path, sections: dict[str, dict[str, Any]]) -> None:
    """Refuse a node of ``sections`` outside the graph, or a parameter its node does not take
    (one under ``/**`` that no node takes)."""
    for name, values in sections.items():
        if name != "/**" and name not in NODES:
            raise InvalidParameterError(f"{path}: unknown node {name!r}; the graph's nodes are {', '.join(NODES)} "
                                        "(and /** for all of them)")
        known = set().union(*(known_parameters(n) for n in (NODES if name == "/**" else (name,))))
        for key in values:
            if key not in known:
                hint = get_close_matches(str(key), known, n=1)
                raise InvalidParameterError(f"{path}: unknown parameter {key!r} of {name}"
                                            + (f" (did you mean {hint[0]!r}?)" if hint else ""))


def load_params(path: Path) -> dict[str, dict[str, Any]]:
    """Parameters per node: the packaged file's (the paper's scenario) with those of ``path`` over
    them, as ROS merges several parameter files (the later file's value wins; ``/**`` entries
    apply to every node). A node or parameter the graph does not know is refused, naming it."""
    given = _sections(path)
    _check_known(path, given)
    defaults = _packaged()
    return {node: {**defaults["/**"], **defaults[node], **given["/**"], **given.get(node, {})} for node in NODES}


def object_parameters(params: dict[str, dict[str, Any]], obj: ObjectSpec) -> dict[str, dict[str, Any]]:
    """The parameters ``obj`` changes: the simulator's object, the controller's adaptive-gain
    radius, the quality evaluator's wrench reference (an outline by its absolute path: the nodes
    may run elsewhere)."""
    if obj.shape == "outline":
        obj = ObjectSpec.from_outline(Path(obj.source).resolve())
    scenario = Scenario.from_ros_parameters(params)
    scenario = scenario.with_object(obj, sensing=replace(scenario.sensing, reference=None))
    new = scenario.to_ros_parameters()
    return {node: new[node] for node in (SIMULATOR, CONTROLLER, QUALITY)}


def launch_overrides(params: dict[str, dict[str, Any]], obj: ObjectSpec | None = None, law: str | None = None,
                     object_mode: str | None = None,
                     max_muscle_stress: float | None = None, friction: float | None = None) -> dict[str, dict[str, Any]]:
    """The parameters per node that a launch's options change: the object (:func:`object_parameters`),
    the controller's ``law``, the simulator's ``object_mode``, the arm's ``max_muscle_stress`` and
    the contact's ``friction`` (stick-slip when > 0, as ``contgrasp simulate --friction``) (the
    simulator's and the controller's: they describe one rod) (None: unchanged); the result,
    merged into ``params``, is checked as a scenario (:meth:`Scenario.from_ros_parameters`: an
    unknown law or mode, an impossible start)."""
    out = {} if obj is None else object_parameters(params, obj)
    if law is not None:
        out.setdefault(CONTROLLER, {})["law"] = law
    if object_mode is not None:
        out.setdefault(SIMULATOR, {})["object_mode"] = object_mode
    rod: dict[str, Any] = {}
    if max_muscle_stress is not None:
        rod["max_muscle_stress"] = float(max_muscle_stress)
    if friction is not None:
        if not (np.isfinite(friction) and friction >= 0):
            raise InvalidParameterError(f"friction must be a finite number >= 0 (Coulomb coefficient), got {friction!r}")
        rod["friction"] = float(friction)
        if friction > 0:
            rod["friction_model"] = "stick"
    for node in (SIMULATOR, CONTROLLER) if rod else ():
        out.setdefault(node, {}).update(rod)
    Scenario.from_ros_parameters({node: {**params[node], **out.get(node, {})} for node in params})
    return out


def recorder_params(record: dict[str, Any]) -> dict[str, Any]:
    """The recorder's parameters for a run: output, layout, run_info (a JSON string), the
    log-time clock (``sim`` by default: lock-step runs are stamped with simulated time), and the
    optional exclusion, decimation and file splitting."""
    log_time = record.get("log_time", "sim")
    out = {"output": str(record["output"]), "layout": record.get("layout", "folder"), "run_info": json.dumps(record.get("run_info", {})),
           "log_time": log_time, "use_sim_time": log_time == "sim"}
    if record.get("exclude_regex"):
        out["exclude_regex"] = record["exclude_regex"]
    if record.get("decimate_period"):
        out["decimate_topics"] = list(DECIMATED_STREAMS)
        out["decimate_period"] = float(record["decimate_period"])
    if record.get("max_bag_duration"):
        out["max_bag_duration"] = float(record["max_bag_duration"])
    if record.get("max_bag_size"):
        out["max_bag_size"] = int(record["max_bag_size"])
    return out


def parameter_file(path: Path, params: dict[str, dict[str, Any]], namespace: str = "/") -> Path:
    """Write ``params`` (per node) to ``path`` as a ROS 2 parameter file for nodes in ``namespace``
    (a section is keyed by the node's name at the root, else by its fully qualified name: a plain
    ``node:`` key names ``/node`` only); returns ``path``."""
    path.write_text(yaml.safe_dump({topics.resolve(node, namespace) if namespace.strip("/") else node: {"ros__parameters": values}
                                    for node, values in params.items()}))
    return path
