"""Writing a recording: MCAP with rosbag2's layout (profile ``ros2``, ``ros2msg`` schemas, ``cdr``).

A :class:`BagWriter` writes either a bag folder (``NAME/NAME_0.mcap`` + ``metadata.yaml``, like
``ros2 bag record -s mcap``) or a single ``.mcap`` file. Messages are collected in chunks
compressed with zstd (or lz4, or none); a chunk is finished and handed to the operating system
when it reaches ``chunk_size`` bytes or when :meth:`BagWriter.flush` is called (the recorder
does so periodically), so a process killed with SIGKILL loses at most the open chunk and every
complete chunk can be recovered (:func:`contgrasp_ros.bag.reader.recover`). Closing writes the
summary and indexes, the ``rosbag2`` metadata record and ``metadata.yaml``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from .definitions import full_text
from .errors import BagError
from .rosbag2 import TopicRecord, bag_metadata, metadata_yaml, offered_qos_yaml

__all__ = ["BagWriter", "COMPRESSIONS", "LAYOUTS", "RUN_RECORD", "RECORDER_RECORD"]

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
LAYOUTS = ("folder", "file")
LIBRARY = "contgrasp mcap_recorder"
RUN_RECORD = "contgrasp_run"  # MCAP metadata record: how the run was made (launcher parameters, argv)
RECORDER_RECORD = "contgrasp_recorder"  # MCAP metadata record: the recorder's received/written counts


@dataclass
class _Topic:
    record: TopicRecord
    channel_id: int
    first_ns: int | None = None
    last_ns: int = 0


@dataclass
class BagWriter:
    """Writes one recording. ``path`` is the bag folder (layout ``folder``, must not exist) or
    the ``.mcap`` file (layout ``file``). ``custom_data`` goes into the bag metadata."""

    path: Path
    layout: str = "folder"
    compression: str = "zstd"
    chunk_size: int = 256 * 1024
    custom_data: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.path = Path(self.path)
        if self.layout not in LAYOUTS:
            raise BagError(f"layout must be one of {LAYOUTS}, got {self.layout!r}")
        if self.compression not in COMPRESSIONS:
            raise BagError(f"compression must be one of {tuple(COMPRESSIONS)}, got {self.compression!r}")
        if not 1024 <= int(self.chunk_size) <= 1 << 30:
            raise BagError(f"chunk_size must be in [1 KiB, 1 GiB], got {self.chunk_size}")
        if self.layout == "folder":
            if self.path.exists():
                raise BagError(f"cannot record to {self.path}: it already exists")
            self.file = self.path / f"{self.path.name}_0.mcap"
        else:
            if self.path.suffix != ".mcap":
                raise BagError(f"a single-file recording must end in .mcap, got {self.path}")
            if self.path.exists():
                raise BagError(f"cannot record to {self.path}: it already exists")
            self.file = self.path
        try:
            self.file.parent.mkdir(parents=True, exist_ok=True)
            self._stream = open(self.file, "xb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise BagError(f"cannot record to {self.file}: {exc.strerror or exc}") from exc
        self._mcap = Writer(
            self._stream, chunk_size=int(self.chunk_size), compression=COMPRESSIONS[self.compression], enable_data_crcs=True
        )
        self._schemas: dict[str, int] = {}
        self.topics: dict[str, _Topic] = {}
        self.records: dict[str, dict[str, str]] = {}  # extra MCAP metadata records written at close
        self.messages = 0
        self.bytes = 0
        self.closed = False
        self._guard(lambda: self._mcap.start(profile="ros2", library=LIBRARY))

    def _guard(self, op: Any) -> Any:
        try:
            return op()
        except OSError as exc:
            raise BagError(f"writing {self.file} failed: {exc.strerror or exc}") from exc

    def add_topic(
        self,
        name: str,
        type_name: str,
        offered_qos: str | Sequence[Mapping[str, Any]] = (),
        type_hash: str = "",
        definition: str | None = None,
    ) -> None:
        """Register a topic: its schema (once per type; the full ``.msg`` text from the installed
        definitions unless ``definition`` is given) and its channel with the
        ``offered_qos_profiles`` (profiles, or the YAML text) and ``topic_type_hash`` metadata."""
        if name in self.topics:
            return
        if type_name not in self._schemas:
            data = (full_text(type_name) if definition is None else definition).encode()
            self._schemas[type_name] = self._guard(lambda: self._mcap.register_schema(type_name, "ros2msg", data))
        qos_text = offered_qos if isinstance(offered_qos, str) else offered_qos_yaml(offered_qos)
        cid = self._guard(
            lambda: self._mcap.register_channel(
                name, "cdr", self._schemas[type_name], {"offered_qos_profiles": qos_text, "topic_type_hash": type_hash}
            )
        )
        self.topics[name] = _Topic(TopicRecord(name, type_name, qos_text, type_hash), cid)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None, sequence: int = 0) -> None:
        """Append one serialized (CDR) message of a registered topic."""
        t = self.topics.get(topic)
        if t is None:
            raise BagError(f"topic {topic!r} was not registered with add_topic")
        pub = log_time_ns if publish_time_ns is None else publish_time_ns
        self._guard(lambda: self._mcap.add_message(t.channel_id, int(log_time_ns), bytes(data), int(pub), int(sequence) & 0xFFFFFFFF))
        t.record.message_count += 1
        t.first_ns = log_time_ns if t.first_ns is None else min(t.first_ns, log_time_ns)
        t.last_ns = max(t.last_ns, log_time_ns)
        self.messages += 1
        self.bytes += len(data)

    def flush(self) -> None:
        """Finish the open chunk and hand everything to the operating system (survives SIGKILL)."""
        self._guard(self._mcap.flush)

    def metadata(self) -> dict[str, Any]:
        """rosbag2 bag metadata of what has been written so far."""
        firsts = [t.first_ns for t in self.topics.values() if t.first_ns is not None]
        start = min(firsts, default=0)
        end = max((t.last_ns for t in self.topics.values()), default=start)
        return bag_metadata(
            files=[(self.file.name, start, end - start, self.messages)],
            topics=[t.record for t in self.topics.values()],
            custom_data=self.custom_data,
        )

    def close(self) -> dict[str, Any]:
        """Write the extra metadata :attr:`records`, the ``rosbag2`` record, the summary, and
        ``metadata.yaml`` (folder layout); returns the bag metadata."""
        if self.closed:
            return self.metadata()
        info = self.metadata()

        def finish() -> None:
            for name, data in self.records.items():
                self._mcap.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": metadata_yaml(info, top_level=False)})
            self._mcap.finish()
            self._stream.close()

        self._guard(finish)
        self.closed = True
        if self.layout == "folder":
            try:
                (self.path / "metadata.yaml").write_text(metadata_yaml(info))
            except OSError as exc:
                raise BagError(f"cannot write {self.path / 'metadata.yaml'}: {exc.strerror or exc}") from exc
        return info
