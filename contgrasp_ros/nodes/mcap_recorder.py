"""mcap_recorder: records the graph's topics to MCAP the way rosbag2's MCAP storage does.

Raw subscriptions to every topic (or a list / regular expression, new topics found mid-run),
written with :class:`contgrasp_ros.bag.writer.BagWriter`; QoS adapted to the publishers' offers
like rosbag2; the open chunk handed to the OS every ``flush_period``; counts (received, written,
``lost_in_transport`` from sequence gaps, decimated) on ``/diagnostics`` and in the file.
Optional bag splitting, simulated-time log times and decimation. Parameters, format, counts and
robustness: docs/recording.md ("The recorder node").
"""

from __future__ import annotations

import functools
import json
import re
import struct
import time
from datetime import datetime
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import QoSSubscriptionMatchedInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from contgrasp_core.errors import InvalidParameterError
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.bag.definitions import full_text
from contgrasp_ros.bag.errors import BagError
from contgrasp_ros.bag.rosbag2 import qos_profile_dict
from contgrasp_ros.bag.writer import (
    COMPRESSIONS,
    LAYOUTS,
    LOG_TIME_RECORD,
    MIN_BAG_SIZE,
    RECORDER_RECORD,
    RUN_RECORD,
    BagWriter,
    check_split,
)
from contgrasp_ros.plumbing.faults import DropCounter, FatalNodeError, guarded
from contgrasp_ros.plumbing.parameters import declare
from contgrasp_ros.plumbing.runtime import FinishPolicy, run_node



def default_output() -> str:
    """``bags/run_YYYYmmdd_HHMMSS`` in the working directory."""
    return str(Path("bags") / datetime.now().strftime("run_%Y%m%d_%H%M%S"))


def _starts_with_stamp(type_name: str) -> bool:
    """The type's first field is a std_msgs/Header or a builtin_interfaces/Time (e.g. /clock)."""
    for line in full_text(type_name).splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            return line.split()[0] in ("std_msgs/Header", "builtin_interfaces/Time", "Header")
    return False


LOG_TIMES = ("receive", "sim")
OTHER_CLOCK_NS = 3600 * 1_000_000_000  # with log_time sim: a stamp this far from /clock is of another clock


def cdr_stamp_ns(data: bytes) -> int:
    """Nanoseconds of the leading stamp of a CDR message (exact; see :func:`cdr_stamp`)."""
    if len(data) < 12:
        raise ValueError("message shorter than a stamp")
    fmt = "<iI" if data[1] == 1 else ">iI"
    sec, nsec = struct.unpack_from(fmt, data, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


def cdr_stamp(data: bytes) -> float:
    """Seconds of the leading stamp of a CDR message (4-byte encapsulation, int32 sec, uint32 nanosec)."""
    if len(data) < 12:
        raise ValueError("message shorter than a stamp")
    fmt = "<iI" if data[1] == 1 else ">iI"
    sec, nsec = struct.unpack_from(fmt, data, 4)
    return sec + 1e-9 * nsec


class McapRecorder(Node):
    """Records raw messages of the selected topics; see the module docstring."""

    def __init__(self, **node_kwargs: Any) -> None:
        # (no /rosout: the recorder's last words, the closed file, come after SIGINT has shut the
        # context down, and rcl would print that it cannot publish them there; they go to the
        # console and the log file as before)
        super().__init__("mcap_recorder", **{"enable_rosout": False, **node_kwargs})
        out = declare(self, "output", "", "bag folder, or .mcap file with layout 'file' ('' = bags/run_<time>)", read_only=True)
        layout = declare(self, "layout", "folder", f"one of {LAYOUTS}", read_only=True)
        compression = declare(self, "compression", "zstd", f"chunk compression, one of {tuple(COMPRESSIONS)}", read_only=True)
        chunk_size = declare(self, "chunk_size", 262144, "chunk size [bytes]", lo=1024, hi=1 << 30, read_only=True)
        max_duration = declare(self, "max_bag_duration", 0.0, "start a new file of the bag folder after this many "
                               "seconds (0 = one file) [s]", lo=0.0, hi=1e9, read_only=True)
        max_size = declare(self, "max_bag_size", 0, f"start a new file of the bag folder at this size (0 = one file, "
                           f"else >= {MIN_BAG_SIZE}) [bytes]", lo=0, hi=1 << 50, read_only=True)
        self.topics = list(declare(self, "topics", [""], "topics to record ([''] = all)", read_only=True))
        regex = declare(self, "regex", "", "also record topics matching this regular expression", read_only=True)
        exclude = declare(self, "exclude_regex", "", "never record topics matching this", read_only=True)
        self.depth = declare(self, "qos_depth", 1000, "subscription queue depth", lo=1, hi=1_000_000, read_only=True)
        flush = declare(self, "flush_period", 0.5, "finish the open chunk at least this often [wall s]", lo=0.01, hi=3600.0, read_only=True)
        discovery = declare(self, "discovery_period", 0.2, "look for new topics this often [wall s]", lo=0.01, hi=3600.0, read_only=True)
        run_info = declare(self, "run_info", "", "JSON object stored in the recording when it opens (metadata record "
                           "contgrasp_run)", read_only=True)
        self.log_time = declare(self, "log_time", "receive", "log time of a message: 'receive' (wall clock at receipt) or "
                                "'sim' (its header stamp, else /clock: simulated time)", choices=LOG_TIMES, read_only=True)
        decimate = [t for t in declare(self, "decimate_topics", [""], "topics to decimate ([''] = none)", read_only=True) if t]
        no_seq = declare(self, "sequence_check_exclude_regex", "/parameter_events|/rosout|/diagnostics",
                         "topics with many publishers: no sequence-gap check ('' = check all)", read_only=True)
        self.decimate_period = declare(self, "decimate_period", 0.0, "keep one message per this many stamp seconds [s]",
                                       lo=0.0, hi=1e6, read_only=True)
        self._decimate: dict[str, list[Any]] = {}  # topic -> [last kept stamp, held (data, info) or None]
        self._decimate_wanted = {self.resolve_topic_name(t) for t in decimate} if self.decimate_period > 0 else set()
        self.decimated = 0
        self._last_seq: dict[str, int | None] = {}
        self._single_publisher: dict[str, bool] = {}
        self.lost_in_transport: dict[str, int] = {}
        self.topics = [self.resolve_topic_name(t) for t in self.topics if t]
        ns = self.get_namespace()
        self.namespace_prefix = "" if ns == "/" else ns + "/"  # (namespaced: only its graph's topics)
        try:
            self.regex = re.compile(regex) if regex else None
            self.exclude = re.compile(exclude) if exclude else None
            self.no_sequence_check = re.compile(no_seq) if no_seq else None
        except re.error as exc:
            raise InvalidParameterError(f"invalid regular expression: {exc}") from exc
        try:
            info = json.loads(run_info) if run_info else {}
            if not isinstance(info, dict):
                raise ValueError("not a JSON object")
        except ValueError as exc:
            raise InvalidParameterError(f"run_info must be a JSON object: {exc}") from exc
        if layout not in LAYOUTS or compression not in COMPRESSIONS:
            raise InvalidParameterError(f"layout must be one of {LAYOUTS} and compression one of {tuple(COMPRESSIONS)}")
        try:
            check_split(layout, max_duration, max_size)
        except BagError as exc:
            raise InvalidParameterError(str(exc)) from exc
        if self.log_time == "sim" and not self.get_parameter("use_sim_time").value:
            self.set_parameters([Parameter("use_sim_time", value=True)])  # the fallback clock is /clock
        opened = {LOG_TIME_RECORD: {"clock": "sim" if self.log_time == "sim" else "wall", "log_time": self.log_time},
                  RUN_RECORD: {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in info.items()}}
        try:
            self.writer = BagWriter(Path(out or default_output()), layout=layout, compression=compression, chunk_size=chunk_size,
                                    max_bag_duration=max_duration, max_bag_size=max_size, open_records=opened)
        except BagError as exc:
            raise FatalNodeError(str(exc)) from exc
        self._stamped: dict[str, bool] = {}
        self.received: dict[str, int] = {}
        self.drops = DropCounter(self)  # (internal errors of the callbacks; nothing is dropped on purpose)
        self.exit_code = 0
        self.finish = FinishPolicy(self, watch_simulator=True)
        self._subs: dict[str, Any] = {}
        self._pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, qos.STREAM)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(discovery, self.discover, clock=steady)
        self.create_timer(flush, self.flush, clock=steady)
        self.get_logger().info(f"recording to {self.writer.path}")
        self.discover()

    # ------------------------------------------------------------------ topics
    def selected(self, topic: str) -> bool:
        """Record ``topic``: in the recorder's namespace or global (another graph's are not), not
        excluded, and chosen by ``topics``/``regex`` when given."""
        if not topic.startswith(self.namespace_prefix) and topic not in topics.GLOBAL:
            return False
        if self.exclude is not None and self.exclude.fullmatch(topic):
            return False
        if not self.topics and self.regex is None:
            return True
        return topic in self.topics or (self.regex is not None and self.regex.fullmatch(topic) is not None)

    def _request_qos(self, offers: list[Any]) -> QoSProfile:
        reliable = all(int(o.qos_profile.reliability) == int(ReliabilityPolicy.RELIABLE) for o in offers)
        latched = all(int(o.qos_profile.durability) == int(DurabilityPolicy.TRANSIENT_LOCAL) for o in offers)
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=self.depth,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )

    @guarded("discovery")
    def discover(self) -> None:
        """Subscribe to selected topics that have publishers and are not recorded yet."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs or not self.selected(topic) or len(types) != 1:
                continue
            offers = self.get_publishers_info_by_topic(topic)
            if not offers:
                continue  # the publishers' QoS are needed (offered_qos_profiles); wait for one
            try:
                cls = topics.message_class(types[0])
            except (ImportError, AttributeError, ValueError):
                self.get_logger().warn(f"not recording {topic}: type {types[0]} is not installed", once=True)
                continue
            try:
                self.writer.add_topic(topic, types[0], [qos_profile_dict(o.qos_profile) for o in offers], str(offers[0].topic_type_hash))
            except BagError as exc:
                raise FatalNodeError(str(exc)) from exc
            self.received[topic] = 0
            self.lost_in_transport[topic] = 0
            try:  # (/rosout's stamps are the wall clock: rcutils logging)
                self._stamped[topic] = types[0] != "rcl_interfaces/msg/Log" and _starts_with_stamp(types[0])
            except Exception:  # noqa: BLE001 - no definition text: use the clock
                self._stamped[topic] = False
            self._single_publisher[topic] = False  # until the matched event says one publisher is matched
            if topic in self._decimate_wanted:
                if _starts_with_stamp(types[0]):
                    self._decimate[topic] = [None, None]
                else:
                    self.get_logger().warn(f"not decimating {topic}: {types[0]} does not start with a stamp")
            checked = self.no_sequence_check is None or not self.no_sequence_check.fullmatch(topic)
            events = SubscriptionEventCallbacks(matched=functools.partial(self.on_matched, topic)) if checked else None
            self._subs[topic] = self.create_subscription(
                cls, topic, functools.partial(self.on_message, topic), self._request_qos(offers),
                event_callbacks=events, raw=True,
            )
            self.get_logger().info(f"recording {topic} [{types[0]}]")

    @guarded("matched event")
    def on_matched(self, topic: str, info: QoSSubscriptionMatchedInfo) -> None:
        """Check sequence numbers only while exactly one publisher is matched; any change of
        publishers starts the count over (a new publisher numbers its messages from 1)."""
        self._single_publisher[topic] = info.current_count == 1
        self._last_seq[topic] = None

    # ------------------------------------------------------------------ messages
    def _track_sequence(self, topic: str, seq: int | None) -> None:
        """Count gaps in a single publisher's sequence numbers (a restarted publisher starts over)."""
        last = self._last_seq.get(topic)
        if not seq or not self._single_publisher.get(topic):
            self._last_seq[topic] = None
            return
        if last is not None and seq > last + 1:
            self.lost_in_transport[topic] += seq - last - 1
        self._last_seq[topic] = seq

    @guarded("recording")
    def on_message(self, topic: str, data: bytes, info: dict[str, Any]) -> None:
        self.received[topic] += 1
        self._track_sequence(topic, info.get("publication_sequence_number"))
        log_ns = self.log_time_ns(topic, data)
        dec = self._decimate.get(topic)
        if dec is not None:
            try:
                t = cdr_stamp(data)
            except ValueError:
                t = None
            if t is not None and dec[0] is not None and 0.0 <= t - dec[0] < self.decimate_period - 1e-12:
                if dec[1] is not None:
                    self.decimated += 1
                dec[1] = (data, info, log_ns)  # held: written at the end if it stays the last one
                return
            if dec[1] is not None:
                self.decimated += 1
            dec[0], dec[1] = t, None
        self._write(topic, data, info, log_ns)

    def log_time_ns(self, topic: str, data: bytes) -> int:
        """The message's log time: receive time (wall), or with ``log_time: sim`` its header
        stamp (when its type starts with one and it is set), else the node's (sim) clock."""
        if self.log_time != "sim":
            return time.time_ns()
        now = int(self.get_clock().now().nanoseconds)
        if self._stamped.get(topic):
            try:
                stamp = cdr_stamp_ns(data)
            except ValueError:
                stamp = 0
            # a stamp of another clock (a publisher on wall time: ~1.7e9 s) is not simulated time
            if stamp > 0 and abs(stamp - now) < OTHER_CLOCK_NS:
                return stamp
        return now

    def _write(self, topic: str, data: bytes, info: dict[str, Any], log_ns: int) -> None:
        try:
            self.writer.write(topic, data, log_ns, info.get("source_timestamp") or None, info.get("publication_sequence_number") or 0)
        except BagError as exc:
            raise FatalNodeError(str(exc)) from exc

    def counts(self) -> dict[str, Any]:
        """Received and written messages, in total and per topic."""
        written = {t: v.record.message_count for t, v in self.writer.topics.items()}
        return {
            "received": sum(self.received.values()),
            "written": sum(written.values()),
            "decimated": self.decimated,
            "held": sum(d[1] is not None for d in self._decimate.values()),
            "lost_in_transport": sum(self.lost_in_transport.values()),
            "bytes": self.writer.bytes,
            "received_per_topic": dict(self.received),
            "written_per_topic": written,
            "lost_in_transport_per_topic": {t: n for t, n in self.lost_in_transport.items() if n},
        }

    @guarded("flush")
    def flush(self) -> None:
        try:
            self.writer.flush()
        except BagError as exc:
            raise FatalNodeError(str(exc)) from exc
        c = self.counts()
        values = {"path": str(self.writer.path), "received": str(c["received"]), "written": str(c["written"]),
                  "decimated": str(c["decimated"]), "lost_in_transport": str(c["lost_in_transport"]),
                  "bytes": str(c["bytes"]), "topics": str(len(self._subs)), "files": str(len(self.writer.files)),
                  **self.drops.key_values()}
        unwritten = c["received"] - c["written"] - c["decimated"] - c["held"]
        ok = unwritten == 0 and c["lost_in_transport"] == 0 and self.drops.total == 0
        level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
        st = DiagnosticStatus(level=level, name=topics.status_name(self.get_name(), self.get_namespace()), message="recording", hardware_id="contgrasp",
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
        self._pub_diag.publish(DiagnosticArray(status=[st]))

    def destroy_node(self) -> None:
        """Finalise the recording (summary, indexes, metadata.yaml) before the node goes."""
        if not self.writer.closed:
            for topic, dec in self._decimate.items():
                if dec[1] is not None:
                    data, info, log_ns = dec[1]
                    dec[1] = None
                    try:
                        self._write(topic, data, info, log_ns)
                    except FatalNodeError as exc:
                        self.get_logger().error(str(exc))
            c = self.counts()
            self.writer.records[RECORDER_RECORD] = {k: json.dumps(v) for k, v in c.items()}
            try:
                self.writer.close()
                self.get_logger().info(
                    f"closed {self.writer.path}: {c['written']} messages written, {c['received']} received, "
                    f"{len(self.writer.topics)} topics"
                )
            except BagError as exc:
                self.get_logger().error(f"could not finalise the recording: {exc}")
                self.exit_code = 1
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """``ros2 run contgrasp_ros mcap_recorder``."""
    return run_node(McapRecorder, args)


if __name__ == "__main__":
    raise SystemExit(main())
