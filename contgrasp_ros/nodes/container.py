"""``ros2 run contgrasp_ros container NODE NODE... [--ros-args ...]``: several of the graph's nodes
in one process, on one executor (ROS 2's composition, for contgrasp's Python nodes).

Each node keeps its name, its parameters (its own section of a ``--params-file``; a ``-p
NAME:=VALUE`` applies to every node of the process that declares NAME), its topics and its
services; a message between two of them crosses no process boundary, at the price of isolation
(a crash of one ends all of them). ``NODE`` is one of :data:`NODE_CLASSES`, each at most once,
built in the order given. The process spins until SIGINT/SIGTERM or until every node asks to
stop, and exits as :func:`contgrasp_ros.plumbing.runtime.run_nodes` says (2 for bad usage or a
refused parameter, 1 for a failure). docs/ros.md, "Composition".
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Sequence

from rclpy.node import Node

from contgrasp_ros.plumbing.runtime import run_nodes

__all__ = ["NODE_CLASSES", "node_class", "main"]

# the graph's nodes (ROS name = module of contgrasp_ros.nodes) and their classes
NODE_CLASSES = {"rod_simulator": "RodSimulator", "boundary_sensor": "BoundarySensor",
                "grasp_controller": "GraspController", "grasp_quality": "GraspQualityNode"}


def node_class(name: str) -> Callable[..., Node]:
    """The class of the graph's node ``name``, built with the node's keyword arguments (its
    module imported now: only the simulator's pulls in scipy and numba)."""
    cls: Callable[..., Node] = getattr(importlib.import_module(f"contgrasp_ros.nodes.{name}"), NODE_CLASSES[name])
    return cls


def main(args: Sequence[str] | None = None) -> int:
    """``ros2 run contgrasp_ros container NODE NODE... [--ros-args ...]``."""
    argv = list(args) if args is not None else sys.argv
    cut = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    names = argv[1:cut]
    usage = f"usage: container NODE [NODE ...] [--ros-args ...] with NODE one of {', '.join(NODE_CLASSES)}"
    if names and names[0] in ("-h", "--help"):
        print(f"{usage}\n\n{__doc__}")
        return 0
    problem = ""
    if not names:
        problem = "name the nodes to host"
    elif unknown := [n for n in names if n not in NODE_CLASSES]:
        problem = f"unknown node(s) {', '.join(unknown)}"
    elif len(set(names)) != len(names):
        problem = "each node at most once (two nodes of one name would clash in the graph)"
    if problem:
        print(f"container: error: {problem}; {usage}", file=sys.stderr)
        return 2
    return run_nodes([node_class(n) for n in names], [argv[0], *argv[cut:]])


if __name__ == "__main__":
    raise SystemExit(main())
