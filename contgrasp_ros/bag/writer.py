"""Writing a recording: MCAP with rosbag2's layout (profile ``ros2``, ``ros2msg`` schemas, ``cdr``).

A :class:`BagWriter` writes a bag folder (``NAME/NAME_0.mcap`` + ``metadata.yaml``, like ``ros2
bag record -s mcap``) or a single ``.mcap`` file, in zstd (or lz4, or plain) chunks finished at
``chunk_size`` or on :meth:`BagWriter.flush`, so a SIGKILL loses at most the open chunk
(:func:`contgrasp_ros.bag.reader.recover`). A bag folder can be split at ``max_bag_duration`` or
``max_bag_size``, every file a complete MCAP file; splitting also bounds the writer's memory.
docs/recording.md ("Format", "Long runs: split the bag").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer

from .definitions import full_text
from .errors import BagInputError, BagIOError
from .rosbag2 import TopicRecord, bag_metadata, metadata_yaml, offered_qos_yaml

__all__ = ["BagWriter", "COMPRESSIONS", "LAYOUTS", "RUN_RECORD", "RECORDER_RECORD", "LOG_TIME_RECORD", "check_file_name", "check_split"]

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
LAYOUTS = ("folder", "file")
LIBRARY = "contgrasp mcap_recorder"
RUN_RECORD = "contgrasp_run"  # MCAP metadata record: how the run was made (launcher parameters, argv)
RECORDER_RECORD = "contgrasp_recorder"  # MCAP metadata record: the recorder's received/written counts
LOG_TIME_RECORD = "contgrasp_log_time"  # MCAP metadata record: which clock the log times are ({"clock": "sim"|"wall"})
MIN_BAG_SIZE = 64 * 1024  # smallest max_bag_size: a split needs room for at least a chunk or two


def _is_int(x: Any) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool)


def _is_real(x: Any) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool) and bool(np.isfinite(x))


def check_split(layout: str, max_bag_duration: float, max_bag_size: int) -> None:
    """Validate the split options (the one rule the writer, the recorder node and the launcher
    apply); raises :class:`BagError` saying what is wrong."""
    if not _is_real(max_bag_duration) or not 0.0 <= max_bag_duration <= 1e9:
        raise BagInputError(f"max_bag_duration must be in [0, 1e9] s (0 = no split), got {max_bag_duration!r}")
    if not _is_int(max_bag_size) or not (max_bag_size == 0 or MIN_BAG_SIZE <= max_bag_size <= 1 << 50):
        raise BagInputError(f"max_bag_size must be 0 (no split) or an integer in [{MIN_BAG_SIZE}, 2**50] bytes, got {max_bag_size!r}")
    if layout == "file" and (max_bag_duration or max_bag_size):
        raise BagInputError("max_bag_duration / max_bag_size split a bag folder; a single .mcap file cannot be split: "
                       "use layout 'folder'")


def check_file_name(layout: str, path: str | Path) -> None:
    """A single-file recording's name ends in ``.mcap`` (the writer's rule, which the launcher
    applies before starting the graph); raises :class:`BagError`."""
    if layout == "file" and Path(path).suffix != ".mcap":
        raise BagInputError(f"a single-file recording must end in .mcap, got {path}")


@dataclass
class _Topic:
    record: TopicRecord
    definition: str
    channel_id: int


@dataclass
class _File:
    """One file of the bag: its name, the log-time span and count of its messages."""

    name: str
    start_ns: int = 0
    end_ns: int = 0
    messages: int = 0

    def add(self, log_time_ns: int) -> None:
        self.start_ns = log_time_ns if not self.messages else min(self.start_ns, log_time_ns)
        self.end_ns = log_time_ns if not self.messages else max(self.end_ns, log_time_ns)
        self.messages += 1


@dataclass
class BagWriter:
    """Writes one recording. ``path`` is the bag folder (layout ``folder``, must not exist) or
    the ``.mcap`` file (layout ``file``). ``custom_data`` goes into the bag metadata.
    ``open_records`` are MCAP metadata records written when each file opens, right after its
    header, and handed to the OS at once: a file cut short by a crash still carries them (the
    run's parameters, the clock of the log times); :attr:`records` are written at close."""

    path: Path
    layout: str = "folder"
    compression: str = "zstd"
    chunk_size: int = 256 * 1024
    custom_data: Mapping[str, str] = field(default_factory=dict)
    max_bag_duration: float = 0.0
    max_bag_size: int = 0
    open_records: Mapping[str, Mapping[str, str]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.path = Path(self.path)
        if not isinstance(self.layout, str) or self.layout not in LAYOUTS:
            raise BagInputError(f"layout must be one of {LAYOUTS}, got {self.layout!r}")
        if not isinstance(self.compression, str) or self.compression not in COMPRESSIONS:
            raise BagInputError(f"compression must be one of {tuple(COMPRESSIONS)}, got {self.compression!r}")
        if not _is_int(self.chunk_size) or not 1024 <= self.chunk_size <= 1 << 30:
            raise BagInputError(f"chunk_size must be an integer in [1 KiB, 1 GiB], got {self.chunk_size!r}")
        check_split(self.layout, self.max_bag_duration, self.max_bag_size)
        self.split = bool(self.max_bag_duration or self.max_bag_size)
        check_file_name(self.layout, self.path)
        if self.path.exists():
            raise BagInputError(f"cannot record to {self.path}: it already exists")
        self.topics: dict[str, _Topic] = {}
        self.records: dict[str, dict[str, str]] = {}  # extra MCAP metadata records written at close
        self.files: list[_File] = []
        self.messages = 0
        self.bytes = 0
        self.closed = False
        self._open_file()

    def _open_file(self) -> None:
        """Start the next file: ``NAME_<k>.mcap`` in a folder, or the ``.mcap`` path itself."""
        name = f"{self.path.name}_{len(self.files)}.mcap" if self.layout == "folder" else self.path.name
        self.file = self.path / name if self.layout == "folder" else self.path
        try:
            self.file.parent.mkdir(parents=True, exist_ok=True)
            self._stream = open(self.file, "xb")  # noqa: SIM115 - closed in _finish_file()
        except OSError as exc:
            raise BagIOError(f"cannot record to {self.file}: {exc.strerror or exc}") from exc
        self._mcap = Writer(
            self._stream, chunk_size=int(self.chunk_size), compression=COMPRESSIONS[self.compression], enable_data_crcs=True
        )
        self._schemas: dict[str, int] = {}
        self.files.append(_File(name))
        self._guard(lambda: self._mcap.start(profile="ros2", library=LIBRARY))
        for name, data in self.open_records.items():
            self._guard(lambda n=name, d=data: self._mcap.add_metadata(n, {str(k): str(v) for k, v in d.items()}))
        if self.open_records:
            self._guard(self._stream.flush)
        for t in self.topics.values():  # every file carries every known topic's schema and channel
            t.channel_id = self._register(t.record.name, t.record.type, t.record.offered_qos_profiles, t.record.type_description_hash,
                                          t.definition)

    def _finish_file(self, info: dict[str, Any]) -> None:
        """Write the metadata records and the summary of the open file and close it."""

        def finish() -> None:
            for name, data in self.records.items():
                self._mcap.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": metadata_yaml(info, top_level=False)})
            self._mcap.finish()
            self._stream.close()

        self._guard(finish)

    def _due_for_split(self, log_time_ns: int) -> bool:
        f = self.files[-1]
        if not self.split or not f.messages:
            return False
        if self.max_bag_duration and log_time_ns - f.start_ns >= self.max_bag_duration * 1e9:
            return True
        return bool(self.max_bag_size) and self._guard(self._stream.tell) >= self.max_bag_size

    def _register(self, name: str, type_name: str, qos_text: str, type_hash: str, definition: str) -> int:
        if type_name not in self._schemas:
            self._schemas[type_name] = self._guard(lambda: self._mcap.register_schema(type_name, "ros2msg", definition.encode()))
        return self._guard(
            lambda: self._mcap.register_channel(
                name, "cdr", self._schemas[type_name], {"offered_qos_profiles": qos_text, "topic_type_hash": type_hash}
            )
        )

    def _guard(self, op: Any) -> Any:
        try:
            return op()
        except OSError as exc:
            raise BagIOError(f"writing {self.file} failed: {exc.strerror or exc}") from exc

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
        text = full_text(type_name) if definition is None else definition
        qos_text = offered_qos if isinstance(offered_qos, str) else offered_qos_yaml(offered_qos)
        cid = self._register(name, type_name, qos_text, type_hash, text)
        self.topics[name] = _Topic(TopicRecord(name, type_name, qos_text, type_hash), text, cid)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None, sequence: int = 0) -> None:
        """Append one serialized (CDR) message of a registered topic."""
        t = self.topics.get(topic)
        if t is None:
            raise BagInputError(f"topic {topic!r} was not registered with add_topic")
        pub = log_time_ns if publish_time_ns is None else publish_time_ns
        if self._due_for_split(log_time_ns):
            self._finish_file(self.metadata())
            self._open_file()
        self._guard(lambda: self._mcap.add_message(t.channel_id, int(log_time_ns), bytes(data), int(pub), int(sequence) & 0xFFFFFFFF))
        self.files[-1].add(log_time_ns)
        t.record.message_count += 1
        self.messages += 1
        self.bytes += len(data)

    def flush(self) -> None:
        """Finish the open chunk and hand everything to the operating system (survives SIGKILL)."""
        self._guard(self._mcap.flush)

    def metadata(self) -> dict[str, Any]:
        """rosbag2 bag metadata of what has been written so far (every file of a split bag)."""
        return bag_metadata(
            files=[(f.name, f.start_ns, f.end_ns - f.start_ns, f.messages) for f in self.files],
            topics=[t.record for t in self.topics.values()],
            custom_data=self.custom_data,
        )

    def close(self) -> dict[str, Any]:
        """Write the extra metadata :attr:`records`, the ``rosbag2`` record, the summary, and
        ``metadata.yaml`` (folder layout); returns the bag metadata."""
        if self.closed:
            return self.metadata()
        info = self.metadata()
        self._finish_file(info)
        self.closed = True
        if self.layout == "folder":
            try:
                (self.path / "metadata.yaml").write_text(metadata_yaml(info))
            except OSError as exc:
                raise BagIOError(f"cannot write {self.path / 'metadata.yaml'}: {exc.strerror or exc}") from exc
        return info
