"""The packages' manifests as rosdep reads them: every dependency key resolves on ROS 2 Jazzy's
Ubuntu 24.04 (noble), and every third-party module the Python packages import is declared.

The keys are checked against ``data/rosdep_keys.json``, a snapshot of rosdistro's key database
(``rosdep/base.yaml``, ``rosdep/python.yaml``) and of the packages released into Jazzy
(``jazzy/distribution.yaml``) at the commit it records; ``data/rosdep_snapshot.py`` rewrites it
from a newer rosdistro clone.
"""

from __future__ import annotations

import ast
import json
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MANIFESTS = {"contgrasp_ros": ROOT / "contgrasp_ros" / "package.xml", "contgrasp_msgs": ROOT / "msgs_schema" / "package.xml"}
PYTHON_PACKAGES = ("contgrasp_core", "contgrasp_ros")
DEPENDS = ("depend", "build_depend", "build_export_depend", "buildtool_depend", "buildtool_export_depend", "exec_depend",
           "test_depend", "doc_depend")

IMPORT_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "matplotlib": "python3-matplotlib",
    "PIL": "python3-pil",
    "yaml": "python3-yaml",
    "tqdm": "python3-tqdm",
    "numba": "python3-numba",
    "filelock": "python3-filelock",
    "mcap": "mcap-ros2-support",  # (no key of its own: mcap-ros2-support depends on it)
    "mcap_ros2": "mcap-ros2-support",
    "rclpy": "rclpy",
    "builtin_interfaces": "builtin_interfaces",
    "rcl_interfaces": "rcl_interfaces",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "rosgraph_msgs": "rosgraph_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "geometry_msgs": "geometry_msgs",
    "visualization_msgs": "visualization_msgs",
    "contgrasp_msgs": "contgrasp_msgs",
    "launch": "launch",
    "launch_ros": "launch_ros",
    "ament_index_python": "ament_index_python",
}
"""Top-level module imported -> the rosdep key that installs it."""

OPTIONAL = {
    "threadpoolctl": ("contgrasp_core/blas.py",),  # no rosdep key: the one-thread BLAS limit is skipped
    "distributed": ("contgrasp_core/executors.py",),  # the library's dask executor (extra 'dist')
    "foxglove": ("contgrasp_ros/nodes/foxglove_bridge.py",),  # no rosdep key: pip install foxglove-sdk
}
"""Modules no key installs, and the only files that may import them (each says what to install
or does without: contgrasp_ros.entry turns the bridge's missing module into one line)."""


def _snapshot() -> dict:
    return json.loads((ROOT / "tests" / "data" / "rosdep_keys.json").read_text())


def _keys(manifest: Path) -> dict[str, list[str]]:
    """Each dependency tag of a package.xml and the keys it lists."""
    root = ET.parse(manifest).getroot()
    return {tag: [(e.text or "").strip() for e in root.findall(tag)] for tag in DEPENDS}


def _imports() -> dict[str, set[str]]:
    """Third-party top-level modules imported anywhere in the Python packages -> the files."""
    own = {*PYTHON_PACKAGES, "__future__"}
    found: dict[str, set[str]] = {}
    for package in PYTHON_PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for top in {n.split(".")[0] for n in names} - own - set(sys.stdlib_module_names):
                    found.setdefault(top, set()).add(path.relative_to(ROOT).as_posix())
    return found


def test_the_snapshot_names_the_rosdistro_commit_it_came_from() -> None:
    snap = _snapshot()
    assert re.fullmatch(r"[0-9a-f]{40}", snap["commit"]) and snap["platform"] == "ubuntu noble"
    # (sanity: a full database, not a list cut down to what the manifests use)
    assert len(snap["rosdep_keys"]) > 2000 and len(snap["jazzy_packages"]) > 2000
    assert snap["rosdep_keys"]["python3-numpy"] == "apt" and "rclpy" in snap["jazzy_packages"]


@pytest.mark.parametrize("package", sorted(MANIFESTS))
def test_every_dependency_key_resolves_on_jazzy_noble(package: str) -> None:
    snap = _snapshot()
    rules, released = snap["rosdep_keys"], set(snap["jazzy_packages"])
    keys = [key for listed in _keys(MANIFESTS[package]).values() for key in listed]
    assert keys and len(keys) == len(set(keys)), keys
    # a key is a package of this workspace, a package released into Jazzy, or a rosdep key with
    # a rule for noble (apt or pip); rosdep does not fall back from debian to ubuntu
    unknown = [k for k in keys if k not in MANIFESTS and k not in released and k not in rules]
    unresolved = [k for k in keys if k in rules and k not in released and rules[k] is None]
    assert not unknown, f"not rosdep keys at rosdistro {snap['commit'][:10]}: {unknown}"
    assert not unresolved, f"no rule for ubuntu noble: {unresolved}"


def test_a_package_with_launch_files_runs_them_with_ros2_launch() -> None:
    assert list((ROOT / "contgrasp_ros" / "launch").glob("*.launch.py"))
    assert "ros2launch" in _keys(MANIFESTS["contgrasp_ros"])["exec_depend"]


def test_every_third_party_import_is_declared_or_optional() -> None:
    imports = _imports()
    assert set(imports) == set(IMPORT_KEYS) | set(OPTIONAL), "update IMPORT_KEYS or OPTIONAL (and the manifest)"
    for module, files in imports.items():
        if module in OPTIONAL:
            assert files <= set(OPTIONAL[module]), (module, files)
    declared = _keys(MANIFESTS["contgrasp_ros"])
    runtime = set(declared["exec_depend"]) | set(declared["depend"])
    assert set(IMPORT_KEYS.values()) <= runtime, set(IMPORT_KEYS.values()) - runtime
    # and nothing declared for Python that no import needs (a stale key)
    python_keys = {k for k in runtime if k.startswith("python3-") or k in _snapshot()["rosdep_keys"]}
    assert python_keys <= set(IMPORT_KEYS.values()), python_keys - set(IMPORT_KEYS.values())


def test_the_layers_interface_packages_are_its_declared_message_imports() -> None:
    """contgrasp_ros.layer.INTERFACES (what replay calls a missing dependency of the layer) is
    every interface package the layer imports, each declared in package.xml."""
    from contgrasp_ros.layer import INTERFACES

    interfaces = {m for m in _imports() if m.endswith(("_msgs", "_srvs", "_interfaces"))}
    assert INTERFACES == interfaces
    declared = _keys(MANIFESTS["contgrasp_ros"])
    assert INTERFACES <= set(declared["exec_depend"]) | set(declared["depend"])
