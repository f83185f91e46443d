"""rosbag2's conventions for what surrounds the messages (ROS 2 Jazzy, bag format version 9).

* ``offered_qos_profiles``: a YAML list of the publishers' QoS, policies as rmw's lower-case
  names (``keep_last``, ``reliable``, ``transient_local``, ``automatic``...) and durations as
  ``{sec, nsec}`` (``rosbag2_storage/qos.cpp``, version >= 9 encoding);
* ``metadata.yaml``: ``rosbag2_bagfile_information`` with version, storage identifier, file
  list, duration, start time, counts and topic metadata (``rosbag2_storage`` metadata_io);
* the MCAP metadata record ``rosbag2`` with key ``serialized_metadata`` holding the same
  information (``rosbag2_storage_mcap`` ``update_metadata``).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import yaml

__all__ = [
    "BAG_VERSION",
    "STORAGE_ID",
    "TopicRecord",
    "qos_profile_dict",
    "offered_qos_yaml",
    "bag_metadata",
    "metadata_yaml",
]

BAG_VERSION = 9
STORAGE_ID = "mcap"
# rmw's policy values and their names (rmw_qos_*_policy_to_str; rosbag2 writes "unknown" for UNKNOWN)
_POLICY_NAMES = {
    "history": ("system_default", "keep_last", "keep_all", "unknown"),
    "reliability": ("system_default", "reliable", "best_effort", "unknown", "best_available"),
    "durability": ("system_default", "transient_local", "volatile", "unknown", "best_available"),
    "liveliness": ("system_default", "automatic", "manual_by_node", "manual_by_topic", "unknown", "best_available"),
}


def _policy(kind: str, value: Any) -> str:
    names = _POLICY_NAMES[kind]
    i = int(value)
    return names[i] if 0 <= i < len(names) else "unknown"


def _duration(ns: int) -> dict[str, int]:
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def qos_profile_dict(qos: Any) -> dict[str, Any]:
    """One QoS profile (an rclpy ``QoSProfile``, e.g. from ``get_publishers_info_by_topic``) in
    rosbag2's YAML form, keys in rosbag2's order. Policies are rmw enum values (or ints);
    durations are rclpy ``Duration`` objects (``.nanoseconds``): the infinite duration
    (2**63 - 1 ns) becomes rmw's ``{sec: 9223372036, nsec: 854775807}``."""
    return {
        "history": _policy("history", qos.history),
        "depth": int(qos.depth),
        "reliability": _policy("reliability", qos.reliability),
        "durability": _policy("durability", qos.durability),
        "deadline": _duration(qos.deadline.nanoseconds),
        "lifespan": _duration(qos.lifespan.nanoseconds),
        "liveliness": _policy("liveliness", qos.liveliness),
        "liveliness_lease_duration": _duration(qos.liveliness_lease_duration.nanoseconds),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


def offered_qos_yaml(profiles: Sequence[Mapping[str, Any]]) -> str:
    """The ``offered_qos_profiles`` string (YAML list, empty string for no publishers)."""
    if not profiles:
        return ""
    return yaml.safe_dump([dict(p) for p in copy.deepcopy(list(profiles))], sort_keys=False, default_flow_style=False)


@dataclass
class TopicRecord:
    """What the bag metadata lists per topic."""

    name: str
    type: str
    offered_qos_profiles: str
    type_description_hash: str
    message_count: int = 0


def bag_metadata(
    *,
    files: Sequence[tuple[str, int, int, int]],
    topics: Sequence[TopicRecord],
    custom_data: Mapping[str, str] | None = None,
    ros_distro: str = "jazzy",
) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` for files given as (relative path, start ns, duration ns, count)."""
    start = min((f[1] for f in files if f[3]), default=0)
    end = max((f[1] + f[2] for f in files if f[3]), default=start)
    return {
        "version": BAG_VERSION,
        "storage_identifier": STORAGE_ID,
        "duration": {"nanoseconds": int(end - start)},
        "starting_time": {"nanoseconds_since_epoch": int(start)},
        "message_count": int(sum(f[3] for f in files)),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": t.offered_qos_profiles,
                    "type_description_hash": t.type_description_hash,
                },
                "message_count": int(t.message_count),
            }
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f[0] for f in files],
        "files": [
            {
                "path": f[0],
                "starting_time": {"nanoseconds_since_epoch": int(f[1])},
                "duration": {"nanoseconds": int(f[2])},
                "message_count": int(f[3]),
            }
            for f in files
        ],
        "custom_data": dict(custom_data or {}),
        "ros_distro": ros_distro,
    }


def metadata_yaml(info: Mapping[str, Any], *, top_level: bool = True) -> str:
    """YAML text of the metadata: the ``metadata.yaml`` file (top_level) or the
    ``serialized_metadata`` value of the MCAP ``rosbag2`` record (the inner mapping)."""
    data = copy.deepcopy(dict(info))  # no YAML anchors for shared sub-dicts
    if top_level:
        data = {"rosbag2_bagfile_information": data}
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
