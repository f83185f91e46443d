"""Reading recordings without ROS: validate, list, iterate (raw or decoded), summarise, recover.

:func:`open_recording` accepts a bag folder (``metadata.yaml`` + ``*.mcap``, as rosbag2 writes
it) or a single ``.mcap`` file and checks it before anything is read: the MCAP magic at both
ends, the footer, the summary CRC and, when the writer recorded one, the CRC of the whole data
section, so a truncated or byte-corrupted file is reported as a :class:`BagError` naming the
file and the problem instead of failing somewhere inside a parser. A file whose recorder was
killed (no summary) is reported as incomplete; :func:`recover` copies every complete, intact
chunk of such a file into a new, finished recording. Messages are decoded with
``mcap-ros2-support`` from the schemas embedded in the file (no message packages needed).
"""

from __future__ import annotations

import io
import re
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema, Statistics
from mcap.stream_reader import StreamReader

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.outputs import check_output

from .errors import BagError, BagInputError, read_error

__all__ = [
    "MAGIC",
    "Recording",
    "RawMessage",
    "open_recording",
    "iter_raw",
    "iter_decoded",
    "info",
    "recover",
    "UNKNOWN",
]

MAGIC = b"\x89MCAP0\r\n"
_FOOTER = struct.Struct("<BQQQI")  # opcode, record length, summary_start, summary_offset_start, summary_crc
_OP_FOOTER, _OP_DATA_END = 0x02, 0x0F


@dataclass(frozen=True)
class RawMessage:
    """One recorded message with its channel's topic, type and definition."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes
    channel: Channel
    schema: Schema | None  # None: a schemaless channel (MCAP allows them)


@dataclass
class Recording:
    """A validated recording: its MCAP file(s), their summaries and the bag's metadata."""

    path: Path
    files: list[Path]
    metadata_yaml: dict[str, Any] | None
    summaries: list[Any] = field(default_factory=list)

    @property
    def channels(self) -> list[tuple[Channel, Schema | None]]:
        out = []
        for s in self.summaries:
            for ch in s.channels.values():
                out.append((ch, s.schemas.get(ch.schema_id)))
        return out

    def metadata_records(self) -> dict[str, dict[str, str]]:
        """The file's MCAP metadata records by name (e.g. ``rosbag2``, ``contgrasp_run``)."""
        out: dict[str, dict[str, str]] = {}
        for f in self.files:
            with _opened(f) as stream:
                try:
                    for m in make_reader(stream).iter_metadata():
                        out[m.name] = dict(m.metadata)
                except Exception as exc:  # noqa: BLE001 - any parser failure is a corrupt file
                    raise BagInputError(f"{f}: corrupt metadata records ({type(exc).__name__}: {exc})") from exc
        return out


def _opened(path: Path) -> io.BufferedReader:
    try:
        return open(path, "rb")  # noqa: SIM115 - used as a context manager by the callers
    except OSError as exc:
        raise read_error(f"cannot open recording {path}: {exc.strerror or exc}", exc) from exc


def _path(path: Any, what: str = "recording") -> Path:
    if not isinstance(path, str | Path) or not str(path) or "\0" in str(path):
        raise BagInputError(f"the {what} must be a file or folder path, got {path!r}")
    return Path(path)


def _file_order(path: Path) -> tuple[str, int, str]:
    """Order of a split bag's files without metadata.yaml: ``NAME_2.mcap`` before ``NAME_10.mcap``."""
    m = re.fullmatch(r"(.*)_(\d+)\.mcap", path.name)
    return (m.group(1), int(m.group(2)), "") if m else (path.stem, -1, path.name)


def _mcap_files(path: Path) -> tuple[list[Path], dict[str, Any] | None]:
    if not path.exists():
        raise BagInputError(f"no recording at {path}")
    if path.is_file():
        return [path], None
    meta_path = path / "metadata.yaml"
    if meta_path.is_file():
        try:
            meta = yaml.safe_load(meta_path.read_text())
            info_ = meta["rosbag2_bagfile_information"]
            files = [path / str(p) for p in info_["relative_file_paths"]]
        except Exception as exc:  # noqa: BLE001 - a malformed YAML file in any way
            raise BagInputError(f"{meta_path} is not a rosbag2 metadata file ({type(exc).__name__}: {exc})") from exc
        if info_.get("storage_identifier") != "mcap":
            raise BagInputError(f"{path} uses storage {info_.get('storage_identifier')!r}, only 'mcap' is supported")
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise BagInputError(f"{path}: metadata.yaml lists missing files {missing}")
        return files, info_
    files = sorted(path.glob("*.mcap"), key=_file_order)
    if not files:
        raise BagInputError(f"{path} holds no metadata.yaml and no .mcap file")
    return files, None


def check_file(path: Path) -> Any:
    """Validate one MCAP file's framing and CRCs; return its summary."""
    data = _read_all(path)
    if len(data) < 2 * len(MAGIC) or not data.startswith(MAGIC):
        raise BagInputError(f"{path} is not an MCAP file (bad or missing magic)")
    if not data.endswith(MAGIC):
        raise BagInputError(
            f"{path} is incomplete: it ends without the MCAP footer (the recorder was killed or the file was "
            f"truncated); `contgrasp bag recover {path} OUT` copies every complete chunk into a new file"
        )
    if len(data) < 2 * len(MAGIC) + _FOOTER.size:
        raise BagInputError(f"{path} is corrupt: {len(data)} bytes are too few for an MCAP file with a footer")
    end = len(data) - len(MAGIC)
    op, length, summary_start, summary_offset_start, summary_crc = _FOOTER.unpack_from(data, end - _FOOTER.size)
    if op != _OP_FOOTER or length != 20:
        raise BagInputError(f"{path} is corrupt: no valid footer record")
    footer_at = end - _FOOTER.size
    if not (len(MAGIC) < summary_start <= footer_at) or not (summary_offset_start == 0 or summary_start <= summary_offset_start <= footer_at):
        raise BagInputError(f"{path} is corrupt: the footer points outside the file")
    if summary_crc and zlib.crc32(data[summary_start : end - 4]) != summary_crc:
        raise BagInputError(f"{path} is corrupt: summary section CRC mismatch")
    de = summary_start - 13
    if de < len(MAGIC) or data[de] != _OP_DATA_END or struct.unpack_from("<Q", data, de + 1)[0] != 4:
        raise BagInputError(f"{path} is corrupt: no data-end record before the summary")
    data_crc = struct.unpack_from("<I", data, de + 9)[0]
    if data_crc and zlib.crc32(data[:de]) != data_crc:
        raise BagInputError(f"{path} is corrupt: data section CRC mismatch (damaged bytes in the recorded messages)")
    try:
        summary = make_reader(io.BytesIO(data), validate_crcs=True).get_summary()
    except Exception as exc:  # noqa: BLE001 - any parser failure means a corrupt file
        raise BagInputError(f"{path} is corrupt: cannot read its summary ({type(exc).__name__}: {exc})") from exc
    if summary is None:
        raise BagInputError(f"{path} has no summary section")
    return summary


def _read_all(path: Path) -> bytes:
    with _opened(path) as f:
        try:
            return f.read()
        except OSError as exc:
            raise read_error(f"cannot read {path}: {exc.strerror or exc}", exc) from exc


def open_recording(path: str | Path) -> Recording:
    """Open and validate a recording (bag folder or ``.mcap`` file); raises :class:`BagError`."""
    p = _path(path)
    files, meta = _mcap_files(p)
    rec = Recording(p, files, meta)
    rec.summaries = [check_file(f) for f in files]
    return rec


def iter_raw(rec: Recording, topics: Iterable[str] | None = None, start_ns: int | None = None, end_ns: int | None = None) -> Iterator[RawMessage]:
    """Messages in log-time order (per file), optionally only some topics / a log-time window."""
    wanted = None if topics is None else list(topics)
    for f in rec.files:
        with _opened(f) as stream:
            reader = make_reader(stream, validate_crcs=True)
            try:
                for schema, channel, msg in reader.iter_messages(topics=wanted, start_time=start_ns, end_time=end_ns, log_time_order=True):
                    yield RawMessage(channel.topic, schema.name if schema else "", msg.log_time, msg.publish_time, msg.sequence, msg.data, channel, schema)
            except BagError:
                raise
            except Exception as exc:  # noqa: BLE001 - any parser failure means a corrupt file
                raise BagInputError(f"{f} is corrupt: {type(exc).__name__}: {exc}") from exc


def iter_decoded(rec: Recording, topics: Iterable[str] | None = None) -> Iterator[tuple[RawMessage, Any]]:
    """(raw message, decoded message object) pairs, decoded from the embedded ``ros2msg`` schemas
    by ``mcap-ros2-support`` (fields as attributes, like the ROS message classes)."""
    from mcap_ros2.decoder import DecoderFactory

    factory = DecoderFactory()
    decoders: dict[int, Any] = {}
    for m in iter_raw(rec, topics):
        if m.schema is None:
            raise BagError(f"no decoder for {m.topic} ({m.channel.message_encoding}): its channel has no schema")
        key = m.schema.id
        if key not in decoders:
            decoders[key] = factory.decoder_for(m.channel.message_encoding, m.schema)
            if decoders[key] is None:
                raise BagInputError(f"no decoder for {m.topic} ({m.channel.message_encoding}, schema {m.schema.encoding})")
        try:
            yield m, decoders[key](m.data)
        except Exception as exc:  # noqa: BLE001 - undecodable payload
            raise BagInputError(f"message on {m.topic} at {m.log_time_ns} ns does not decode as {m.type}: {exc}") from exc


def info(rec: Recording) -> dict[str, Any]:
    """What ``ros2 bag info`` shows: files, size, duration, start/end, counts, topics with QoS."""
    topics: dict[str, dict[str, Any]] = {}
    start, end, count, chunks, compression = None, None, 0, 0, set()
    for s in rec.summaries:
        st = s.statistics
        if st is not None and st.message_count:
            start = st.message_start_time if start is None else min(start, st.message_start_time)
            end = st.message_end_time if end is None else max(end, st.message_end_time)
            count += st.message_count
            chunks += st.chunk_count
        compression |= {ci.compression or "none" for ci in s.chunk_indexes}
        for cid, ch in s.channels.items():
            schema = s.schemas.get(ch.schema_id)
            t = topics.setdefault(
                ch.topic,
                {"name": ch.topic, "type": schema.name if schema else "", "count": 0, "serialization_format": ch.message_encoding,
                 "offered_qos_profiles": _qos(ch.metadata.get("offered_qos_profiles", "")),
                 "topic_type_hash": ch.metadata.get("topic_type_hash", "")},
            )
            t["count"] += int(st.channel_message_counts.get(cid, 0)) if st is not None else 0
    start = start or 0
    end = end if end is not None else start
    clock = log_time_clock(rec)
    span = (end - start) * 1e-9
    return {
        "path": str(rec.path),
        "files": [str(f) for f in rec.files],
        "storage_identifier": "mcap",
        "size_bytes": sum(f.stat().st_size for f in rec.files),
        "log_time_clock": clock,
        "sim_time_s": span if clock == "sim" else None,
        "wall_time_s": span if clock == "wall" else None,
        "start_ns": start,
        "end_ns": end,
        "message_count": count,
        "chunk_count": chunks,
        "compression": sorted(compression),
        "topics": sorted(topics.values(), key=lambda t: t["name"]),
    }


def log_time_clock(rec: Recording) -> str:
    """Which clock the recording's log times are: ``sim`` (simulated time: message header stamps
    and ``/clock``, as ``ros2 bag record --use-sim-time``) or ``wall`` (receive time, rosbag2's
    default), from the ``contgrasp_log_time`` metadata record; ``wall`` without one."""
    from .writer import LOG_TIME_RECORD

    clock = rec.metadata_records().get(LOG_TIME_RECORD, {}).get("clock", "wall")
    return "sim" if clock == "sim" else "wall"


def _qos(text: str) -> list[dict[str, Any]] | str:
    try:
        out = yaml.safe_load(text) if text else []
    except yaml.YAMLError:
        return text
    return out if isinstance(out, list) else text


def _records(data: bytes, start: int) -> Iterator[bytes | None]:
    """The bytes of each top-level record from ``start``; ``None`` when the file ends inside one."""
    off = start
    while off + 9 <= len(data):
        length = struct.unpack_from("<Q", data, off + 1)[0]
        if off + 9 + length > len(data):
            yield None
            return
        yield data[off : off + 9 + length]
        off += 9 + length


def _parse_record(raw: bytes) -> list[Any]:
    """The records inside one complete top-level record (a chunk's contents, CRC-checked)."""
    bio = io.BytesIO(raw)
    out = []
    try:
        for r in StreamReader(bio, skip_magic=True, emit_chunks=False, validate_crcs=True).records:
            out.append(r)
    except EndOfFile:  # the stream reader expects a footer after the last record
        if bio.tell() != len(raw):
            raise
    return out


UNKNOWN = "unknown"
"""What :func:`recover` reports for a loss it cannot count: the file's end, with its statistics, is gone."""


def _check_recovered(dst: Path, layout: str) -> None:
    """The recovered recording ``dst`` must be new and creatable (a :class:`BagInputError` before
    any work: :func:`contgrasp_core.outputs.check_output` tries a probe file where it goes)."""
    if dst.exists():
        raise BagInputError(f"the recovered recording {dst} already exists: give a new path")
    try:
        check_output(dst, "the recovered recording", folder=layout == "folder")
    except InvalidParameterError as exc:
        raise BagInputError(str(exc)) from None


def recover(src: str | Path, dst: str | Path, *, layout: str | None = None) -> dict[str, Any]:
    """Copy every intact record of a damaged or unfinished recording into a finished one.

    Each top-level record is parsed on its own (chunks are decompressed and CRC-checked), so a
    corrupt chunk is skipped and counted while the ones after it are kept; the scan ends at the
    first record that runs past the end of the file (where a killed recorder stopped). Returns
    counts of kept chunks and messages, what was lost (:func:`_losses`: against the recording's
    own statistics, or :data:`UNKNOWN`) and the new recording's metadata.
    """
    from .writer import BagWriter

    src_p, dst_p = _path(src), _path(dst, "output")
    files, meta = _mcap_files(src_p)
    layout = layout or ("file" if dst_p.suffix == ".mcap" else "folder")
    _check_recovered(dst_p, layout)
    for f in files:  # before the output is created: a wrong input leaves nothing behind
        with _opened(f) as stream:
            if stream.read(len(MAGIC)) != MAGIC:
                raise BagInputError(f"{f} is not an MCAP file (bad or missing magic)")
    stats: dict[str, Any] = {"chunks_kept": 0, "chunks_lost": UNKNOWN, "records_lost": UNKNOWN, "messages": 0,
                             "messages_without_channel": 0, "truncated": False}
    scans: list[_Scan] = []
    out = BagWriter(dst_p, layout=layout)
    try:
        for f in files:
            data = _read_all(f)
            if not data.startswith(MAGIC):
                raise BagInputError(f"{f} is not an MCAP file (bad or missing magic)")
            scan = _Scan(listed=_listed_count(meta, src_p, f))
            scans.append(scan)
            schemas: dict[int, Schema] = {}
            channels: dict[int, Channel] = {}
            for raw in _records(data, len(MAGIC)):
                if raw is None:
                    stats["truncated"] = True
                    break
                scan.data_end = scan.data_end or raw[0] == _OP_DATA_END
                try:
                    parsed = _parse_record(raw)
                except Exception:  # noqa: BLE001 - a damaged record of any kind is skipped and counted
                    if raw[0] == 0x06:
                        scan.chunks_lost += 1
                    else:
                        scan.records_lost += 1
                    continue
                if raw[0] == 0x06:
                    scan.chunks += 1
                for r in parsed:
                    if isinstance(r, Schema):
                        schemas[r.id] = r
                    elif isinstance(r, Channel):
                        channels[r.id] = r
                    elif isinstance(r, Statistics):
                        scan.statistics = r
                    elif isinstance(r, Message):
                        scan.messages += 1
                        ch = channels.get(r.channel_id)
                        sc = schemas.get(ch.schema_id) if ch else None
                        if ch is None or sc is None:
                            stats["messages_without_channel"] += 1
                            continue
                        out.add_topic(ch.topic, sc.name, ch.metadata.get("offered_qos_profiles", ""),
                                      ch.metadata.get("topic_type_hash", ""), definition=sc.data.decode(errors="replace"))
                        out.write(ch.topic, r.data, r.log_time, r.publish_time, r.sequence)
                        stats["messages"] += 1
                    elif isinstance(r, Metadata) and r.name != "rosbag2":
                        out.records[r.name] = dict(r.metadata)
            stats["chunks_kept"] += scan.chunks
    finally:
        meta_out = out.close()
    stats.update(_losses(scans, stats["messages"]))
    # ``chunks_kept``/``chunks_lost`` count the input's chunks; the copy is chunked anew by the
    # writer, so its own count (what ``bag info`` of the output shows) is reported beside them
    return {**stats, "output_chunks": info(open_recording(dst_p))["chunk_count"], "output": str(dst_p), "metadata": meta_out}


@dataclass
class _Scan:
    """What :func:`recover` found in one file: intact chunks and messages, damaged records, whether
    the data section's end was reached, the file's own statistics record if it survived, and the
    message count ``metadata.yaml`` lists for the file (None: not listed)."""

    listed: int | None = None
    chunks: int = 0
    messages: int = 0
    chunks_lost: int = 0
    records_lost: int = 0
    data_end: bool = False
    statistics: Statistics | None = None

    def losses(self) -> dict[str, int | str]:
        """Chunks, other records and messages lost in this file, each :data:`UNKNOWN` when it
        cannot be counted: the chunks against the statistics' count, else those found damaged
        when the scan reached the data's end (otherwise the end is gone, with what was in it);
        the messages against the statistics', else against ``metadata.yaml``'s, else against
        those found when every chunk was intact."""
        st = self.statistics
        chunks: int | str = st.chunk_count - self.chunks if st else self.chunks_lost if self.data_end else UNKNOWN
        expected = st.message_count if st else self.listed
        if expected is None and self.data_end and not self.chunks_lost:
            expected = self.messages
        return {"chunks_lost": chunks, "records_lost": self.records_lost if self.data_end else UNKNOWN,
                "messages_expected": UNKNOWN if expected is None else expected}


def _losses(scans: list[_Scan], written: int) -> dict[str, int | str]:
    """The files' losses summed (:data:`UNKNOWN` if any file's is), and ``messages_lost``: the
    expected messages that were not ``written``."""
    per_file = [s.losses() for s in scans]
    out: dict[str, int | str] = {}
    for key in ("chunks_lost", "records_lost", "messages_expected"):
        values = [p[key] for p in per_file]
        out[key] = sum(v for v in values if isinstance(v, int)) if all(isinstance(v, int) for v in values) else UNKNOWN
    expected = out["messages_expected"]
    out["messages_lost"] = expected - written if isinstance(expected, int) else UNKNOWN
    return out


def _listed_count(meta: dict[str, Any] | None, folder: Path, file: Path) -> int | None:
    """The message count ``metadata.yaml`` (``meta``, of the bag ``folder``) lists for ``file``."""
    for entry in (meta or {}).get("files") or []:
        if isinstance(entry, dict) and folder / str(entry.get("path")) == file and isinstance(entry.get("message_count"), int):
            return int(entry["message_count"])
    return None
