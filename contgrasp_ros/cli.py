"""The recording subcommands of ``contgrasp``: ``bag info BAG``, ``bag recover IN OUT``,
``replay BAG`` and ``analyze BAG``.

:mod:`contgrasp_core.cli` finds :func:`register` through the ``contgrasp.cli`` entry point, so
the core never imports this layer. Nothing here is imported before a subcommand runs: without
the layer's dependencies (mcap for the recordings, rclpy for ``replay``) the subcommand says in
one line what to install (exit 2, :mod:`contgrasp_ros.layer`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from contgrasp_ros.recordings import cli_analyze
from contgrasp_ros.layer import guarded

__all__ = ["register", "qos_text"]


def _info_text(result: dict[str, Any]) -> str:
    lines = [
        f"Files:             {', '.join(result['files'])}",
        f"Bag size:          {result['size_bytes'] / 1e6:.3f} MB",
        "Storage id:        mcap",
        f"Duration:          {result[result['log_time_clock'] + '_time_s']:.6f} s ({result['log_time_clock']} time)",
        f"Start:             {result['start_ns'] * 1e-9:.9f}",
        f"End:               {result['end_ns'] * 1e-9:.9f}",
        f"Messages:          {result['message_count']}",
        f"Chunks:            {result['chunk_count']} ({', '.join(result['compression']) or 'none'})",
        "Topic information:",
    ]
    for t in result["topics"]:
        lines.append(
            f"  Topic: {t['name']} | Type: {t['type']} | Count: {t['count']} | Serialization Format: {t['serialization_format']}"
            + qos_text(t["offered_qos_profiles"])
        )
    return "\n".join(lines)


def _profile_text(q: dict[str, Any]) -> str:
    history = str(q.get("history", "unknown"))
    # as rclpy's TopicEndpointInfo (``ros2 topic info --verbose``) prints it: the depth only means
    # something for keep_last; a publisher's history is not advertised, so rosbag2 records it as
    # "unknown" with depth 0
    depth = f" ({q.get('depth')})" if history == "keep_last" else ""
    return f"Reliability: {q.get('reliability', 'unknown')}, History (Depth): {history}{depth}, Durability: {q.get('durability', 'unknown')}"


def qos_text(profiles: Any) -> str:
    """The `` | QoS: ...`` part of a topic line of ``contgrasp bag info``: the recorded
    ``offered_qos_profiles`` (rosbag2's YAML list, one profile per publisher) with rclpy's field
    names; publishers with the same profile are counted once. ``ros2 bag info`` itself prints no
    QoS; this follows ``ros2 topic info --verbose``."""
    if isinstance(profiles, str):
        return f" | QoS: {profiles}" if profiles else ""
    if not isinstance(profiles, list) or not profiles:
        return ""
    texts: dict[str, int] = {}
    for q in profiles:
        text = _profile_text(q) if isinstance(q, dict) else str(q)
        texts[text] = texts.get(text, 0) + 1
    n = len(profiles)
    parts = [text if len(texts) == 1 else f"{count} x {text}" for text, count in texts.items()]
    return f" | QoS ({n} publisher{'s' if n != 1 else ''}): " + "; ".join(parts)


@guarded
def _bag_info(args: argparse.Namespace) -> dict[str, Any]:
    from contgrasp_ros.bag.reader import info, open_recording

    return info(open_recording(args.bag))


@guarded
def _bag_recover(args: argparse.Namespace) -> dict[str, Any]:
    from contgrasp_ros.bag.reader import recover

    out = recover(args.input, args.output)
    out.pop("metadata", None)
    return out


@guarded
def _replay(args: argparse.Namespace) -> dict[str, Any]:
    from contgrasp_ros.recordings.replay import replay

    return replay(args.bag, rate=args.rate, topics=args.topics, loop=args.loop, start=args.start, end=args.end, delay=args.delay,
                  wait_for_subscribers=args.wait_for_subscribers)


def register(sub: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add ``bag info``, ``bag recover``, ``replay`` and ``analyze`` to the ``contgrasp`` parser."""
    bag = sub.add_parser("bag", help="inspect or repair recordings (MCAP, rosbag2 layout)",
                         description="Inspect (info) or repair (recover) a recording: a rosbag2 bag folder "
                         "(metadata.yaml and .mcap files) or one .mcap file. No ROS needed.")
    bag_sub = bag.add_subparsers(dest="bag_command", metavar="BAG_COMMAND", required=True)
    p = bag_sub.add_parser("info", parents=parents, help="topics, types, counts, duration, QoS (like ros2 bag info)",
                           description="What ros2 bag info shows: files, size, the log times' clock and span, message "
                           "and chunk counts, and per topic its type, count and its publishers' QoS. No ROS needed.")
    p.add_argument("bag", type=Path, help="bag folder or .mcap file")
    p.set_defaults(func=_bag_info, format_text=_info_text)
    p = bag_sub.add_parser("recover", parents=parents,
                           help="copy every intact chunk of a truncated/damaged recording into a new, finished one",
                           description="Copy every intact chunk and metadata record of a truncated or damaged "
                           "recording into a new, finished one, and say what was lost (against the recording's own "
                           "statistics where they survived, else \"unknown\"). No ROS needed.")
    p.add_argument("input", type=Path, help="damaged bag folder or .mcap file")
    p.add_argument("output", type=Path, help="new recording: a folder, or a .mcap file")
    p.set_defaults(func=_bag_recover)
    p = sub.add_parser("replay", parents=parents, help="republish a recording with its original timing (needs ROS)",
                       description="Republish a recording's messages with their original timing (divided by --rate), "
                       "each topic with the type and QoS its publishers offered, /clock included when it was recorded, "
                       "so the nodes, RViz or Foxglove run against a recorded run. Needs ROS.")
    p.add_argument("bag", type=Path, help="bag folder or .mcap file")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (2 = twice as fast)")
    p.add_argument("--topics", nargs="+", default=None, help="only these topics")
    p.add_argument("--loop", action="store_true", help="start over at the end (stop with Ctrl-C)")
    p.add_argument("--start", type=float, default=None, help="seconds after the first message to start at")
    p.add_argument("--end", type=float, default=None, help="seconds after the first message to stop at")
    p.add_argument("--delay", type=float, default=1.0, help="wall seconds to let subscribers connect first")
    p.add_argument("--wait-for-subscribers", action="store_true",
                   help="before --delay, wait until every replayed topic has a subscriber (Ctrl-C stops the wait)")
    p.set_defaults(func=_replay)
    cli_analyze.add_parser(sub, parents)
