"""Replay a recording: republish its raw (CDR) messages with their original timing.

Publishers get the type and QoS the recording's channels offered (``offered_qos_profiles``:
reliability and durability of the first publisher, like ``ros2 bag play``); messages go out in
log-time order at their recorded spacing divided by ``rate``, including ``/clock`` when it was
recorded, so the sensing/controller/quality nodes, RViz or Foxglove can run against a run.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from contgrasp_core.errors import InvalidParameterError, MissingDependencyError, RunFailure
from contgrasp_ros.bag.reader import Recording, info, iter_raw, open_recording
from contgrasp_ros.layer import INTERFACES, missing
from contgrasp_ros.plumbing.topics import message_class

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.qos import QoSProfile

__all__ = ["replay"]


def _qos(offered: Any) -> QoSProfile:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    first = offered[0] if isinstance(offered, list) and offered and isinstance(offered[0], dict) else {}
    latched = first.get("durability") == "transient_local"
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=1 if latched else 1000,
        reliability=ReliabilityPolicy.BEST_EFFORT if first.get("reliability") == "best_effort" else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def _message_class(type_name: str) -> Any:
    """The class to publish ``type_name`` with. A missing package this layer itself needs is a
    missing dependency (exit 2, saying what to install); any other package or type this
    installation lacks fails the replay (exit 1)."""
    try:
        return message_class(type_name)
    except ModuleNotFoundError as exc:
        hint = missing(exc) if type_name.split("/")[0] in INTERFACES else None
        if hint is not None:
            raise MissingDependencyError(f"cannot replay {type_name}: {hint}") from exc
        raise RunFailure(f"cannot replay {type_name}: the message package is not installed ({exc})") from exc
    except (ImportError, AttributeError, ValueError) as exc:
        raise RunFailure(f"cannot replay {type_name}: the installed message package does not define it ({exc})") from exc


def replay(
    path: str | Path,
    *,
    rate: float = 1.0,
    topics: Sequence[str] | None = None,
    loop: bool = False,
    start: float | None = None,
    end: float | None = None,
    delay: float = 1.0,
    wait_for_subscribers: bool = False,
    ack_timeout: float = 5.0,
    node: Node | None = None,
) -> dict[str, Any]:
    """Republish a recording; ``start``/``end`` are seconds from its first message. Returns counts.

    ``delay`` wall seconds pass between creating the publishers and the first message, so
    subscribers can match; with ``wait_for_subscribers`` the replay first waits (Ctrl-C stops it)
    until every replayed topic has a matched subscriber (a recorder that learns a topic's type
    from the replay's own publisher subscribes only after it saw it, however long that takes on a
    loaded machine), then ``delay``; at the end up to ``ack_timeout`` seconds are given to reliable
    subscribers to acknowledge the last messages. With ``node`` given the caller owns rclpy's
    init and the node.
    """
    if not (rate > 0 and rate < 1e6):
        raise InvalidParameterError(f"--rate must be in (0, 1e6), got {rate}")
    for name, value in (("--start", start), ("--end", end)):
        if value is not None and not (math.isfinite(value) and 0.0 <= value <= 1e9):
            raise InvalidParameterError(f"{name} must be seconds in [0, 1e9] after the first message, got {value}")
    if not (math.isfinite(delay) and 0.0 <= delay <= 3600.0):
        raise InvalidParameterError(f"--delay must be in [0, 3600] s, got {delay}")
    if topics is not None and (isinstance(topics, str) or not all(isinstance(t, str) for t in topics)):
        raise InvalidParameterError(f"topics must be a list of topic names, got {topics!r}")
    rec: Recording = open_recording(path)
    meta = info(rec)
    known = {t["name"]: t for t in meta["topics"]}
    chosen = list(known) if not topics else list(topics)
    missing = [t for t in chosen if t not in known]
    if missing:
        raise InvalidParameterError(f"{path} has no topics {missing}; it has {sorted(known)}")
    t0 = meta["start_ns"]
    lo = None if start is None else t0 + int(start * 1e9)
    hi = None if end is None else t0 + int(end * 1e9)
    if lo is not None and hi is not None and hi < lo:
        raise InvalidParameterError("--end must not be before --start")
    if lo is not None and meta["end_ns"] is not None and lo > meta["end_ns"]:  # (nothing would be published)
        raise InvalidParameterError(f"--start {start:g} s is after the recording's end "
                                    f"({(meta['end_ns'] - t0) / 1e9:g} s after its first message)")
    classes = {t: _message_class(known[t]["type"]) for t in chosen}
    import rclpy  # only now: everything above works (and fails cleanly) without ROS

    own = node is None
    if node is None:
        rclpy.init(args=[])
        node = rclpy.create_node("contgrasp_replay")
    published = dict.fromkeys(chosen, 0)
    wall0 = time.monotonic()
    pubs: dict[str, Any] = {}
    try:
        pubs = {t: node.create_publisher(classes[t], t, _qos(known[t]["offered_qos_profiles"])) for t in chosen}
        while wait_for_subscribers and not all(pub.get_subscription_count() > 0 for pub in pubs.values()):
            time.sleep(0.05)
        time.sleep(max(delay, 0.0))
        wall0 = time.monotonic()
        while True:
            first_ns: int | None = None
            begin = time.monotonic()
            for m in iter_raw(rec, chosen, lo, None if hi is None else hi + 1):
                first_ns = m.log_time_ns if first_ns is None else first_ns
                due = begin + (m.log_time_ns - first_ns) * 1e-9 / rate
                pause = due - time.monotonic()
                if pause > 0:
                    time.sleep(pause)
                try:
                    pubs[m.topic].publish(m.data)
                except Exception:
                    if node.context.ok():
                        raise
                    return _summary(path, rate, published, wall0)  # (SIGINT shut the context down mid-loop)
                published[m.topic] += 1
            if not loop or first_ns is None:
                break
    except KeyboardInterrupt:
        pass
    finally:
        # reliable subscribers still being served: let them acknowledge before the publishers go
        # (after Ctrl-C rclpy has shut the context down, at any moment: all_acked then gives up)
        from contgrasp_ros.plumbing.runtime import all_acked, join_signal_thread

        for pub in pubs.values():
            all_acked(pub, ack_timeout, node.context)
        if own:
            join_signal_thread()
            node.destroy_node()
            if rclpy.ok():
                rclpy.shutdown()
    return _summary(path, rate, published, wall0)


def _summary(path: str | Path, rate: float, published: dict[str, int], wall0: float) -> dict[str, Any]:
    """The replay's counts (also of one stopped early)."""
    return {"path": str(path), "rate": rate, "published": sum(published.values()), "topics": published,
            "wall_time_s": time.monotonic() - wall0}
