"""Full message-definition text of a ROS 2 type, as rosbag2 stores it in an MCAP schema.

rosbag2 (``rosbag2_cpp`` ``LocalMessageDefinitionSource::get_full_text``, encoding ``ros2msg``)
takes the type's own ``.msg`` file from ``share/<pkg>/msg/`` and then, depth first and for each
dependency not yet included (dependencies of a definition in sorted order), appends a newline,
a line of 80 ``=``, a line ``MSG: pkg/Type`` and that type's text. Dependencies are the field
types found by the regular expression below (primitive types excluded; unqualified names are
in the package of the definition that uses them).
"""

from __future__ import annotations

import os
import re
import sys
from functools import lru_cache
from pathlib import Path

from .errors import BagInputError

__all__ = ["SEPARATOR", "full_text", "msg_dependencies", "split_type", "share_dirs"]

SEPARATOR = "=" * 80
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = frozenset(
    {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "string"}
)
_NAME = r"[a-zA-Z][a-zA-Z0-9_]*"
_TYPE = re.compile(rf"^({_NAME})/(?:({_NAME})/)?({_NAME})$")


def split_type(type_name: str) -> tuple[str, str, str]:
    """``pkg/msg/Type`` or ``pkg/Type`` -> (pkg, namespace, Type)."""
    m = _TYPE.match(type_name)
    if m is None:
        raise BagInputError(f"not a ROS 2 message type name: {type_name!r}")
    return m.group(1), m.group(2) or "msg", m.group(3)


def share_dirs() -> list[Path]:
    """Where ``share/<pkg>`` folders are looked up: the ament prefixes, then this interpreter's prefix."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in dict.fromkeys(prefixes)]


@lru_cache(maxsize=None)
def _msg_text(pkg: str, ns: str, name: str) -> str:
    for share in share_dirs():
        path = share / pkg / ns / f"{name}.msg"
        if path.is_file():
            return path.read_text()
    raise BagInputError(f"no definition {pkg}/{ns}/{name}.msg in {', '.join(map(str, share_dirs()))}")


def msg_dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of a ``.msg`` text as ``pkg/Type``, sorted (rosbag2 uses a std::set)."""
    deps = set()
    for m in _FIELD_TYPE.finditer(text):
        t = m.group(1)
        if t in _PRIMITIVES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def full_text(type_name: str) -> str:
    """The concatenated definition of ``type_name`` (schema data of encoding ``ros2msg``)."""
    seen: set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise BagInputError(f"definition of {type_name} nests too deeply")
        pkg, ns, base = split_type(name)
        text = _msg_text(pkg, ns, base)
        out = text
        for dep in msg_dependencies(text, pkg):
            if dep not in seen:
                seen.add(dep)
                out += f"\n{SEPARATOR}\nMSG: {dep}\n" + append(dep, depth - 1)
        return out

    return append(type_name, 50)
