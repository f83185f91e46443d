"""Recording to MCAP (contgrasp_ros.bag, mcap_recorder, replay): conventions checked against
rosbag2's documented formats and two independent readers (mcap-ros2-support, rosbags)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

rclpy = pytest.importorskip("rclpy")

from conftest import fresh_domain_id  # noqa: E402

from contgrasp_ros.bag import BagError  # noqa: E402
from contgrasp_ros.bag.reader import info, iter_decoded, iter_raw, open_recording, recover  # noqa: E402
from contgrasp_ros.bag.writer import RECORDER_RECORD, RUN_RECORD, BagWriter  # noqa: E402

pytestmark = pytest.mark.heavy(per_module=True)  # (its tests share one recorded graph run: one shard makes it)

BIN = Path(sys.executable).parent
SHARE = Path(sys.prefix) / "share"
RULE = "=" * 80


def ros_env(domain: int) -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")


@pytest.fixture(scope="module")
def graph_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """A short closed-loop run of the real graph (separate processes), recorded as a bag folder."""
    out = tmp_path_factory.mktemp("rec") / "run"
    proc = subprocess.run(
        [str(BIN / "contgrasp-launch"), "--domain-id", str(fresh_domain_id()), "--duration", "0.1", "--bag", str(out), "--json"],
        capture_output=True, text=True, timeout=600, env=ros_env(0),
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    # the recorder's last log lines come after SIGINT shut its context down (rcl once printed
    # "Failed to publish log message to rosout: publisher's context is invalid" on every run)
    assert "Failed to publish log message to rosout" not in proc.stderr, proc.stderr[-3000:]
    # nor a hint to reset or Ctrl-C nodes the launcher stops itself
    assert "staying up" not in proc.stderr and "~/reset" not in proc.stderr, proc.stderr[-3000:]
    return out, json.loads(proc.stdout)


# ---------------------------------------------------------------- conventions


def test_full_rate_run_is_recorded_completely(graph_bag: tuple[Path, dict]) -> None:
    """Every message the recorder received was written; every simulation step is in the bag."""
    path, summary = graph_bag
    bag = summary["bag"]
    assert "error" not in bag, bag
    assert bag["received"] == bag["written"] == bag["messages"] > 0
    assert summary["exit_codes"]["mcap_recorder"] == 0
    steps = [m.step for _, m in iter_decoded(open_recording(path), ["/contgrasp/rod_state"])]
    assert steps == list(range(summary["steps"] + 1))  # states 0..k: none lost, none duplicated
    for topic in ("/contgrasp/contact", "/contgrasp/couple"):
        assert bag["topics"][topic] == summary["steps"] + 1  # (the controller answers the final state too)
    # /clock every clock_period (0.01 s, default.yaml) of the 2 ms steps, and the final state's
    clock = [m.clock.sec + 1e-9 * m.clock.nanosec for _, m in iter_decoded(open_recording(path), ["/clock"])]
    assert clock[0] == 0.0 and clock[-1] == pytest.approx(summary["sim_time_s"], abs=1e-9)
    assert np.allclose(np.diff(clock[:-1]), 0.01, atol=1e-9) and 0.0 < clock[-1] - clock[-2] <= 0.01 + 1e-9
    # the observers' streams: every sample_period (0.01 s = 5 steps) and the final state; the
    # sensor's sampled contact states are exactly those steps
    sampled = [m.step for _, m in iter_decoded(open_recording(path), ["/contgrasp/rod_state/sampled"])]
    contact = [m.step for _, m in iter_decoded(open_recording(path), ["/contgrasp/contact/sampled"])]
    assert sampled == sorted({*range(0, summary["steps"] + 1, 5), summary["steps"]})
    assert sorted(contact) == sampled


def test_bag_follows_rosbag2_mcap_conventions(graph_bag: tuple[Path, dict]) -> None:
    """Profile ros2, schema encoding ros2msg with rosbag2's concatenated definition text,
    message encoding cdr, channel metadata offered_qos_profiles (rosbag2's v9 YAML) and
    topic_type_hash, the rosbag2 metadata record and metadata.yaml."""
    from mcap.reader import make_reader

    path, _ = graph_bag
    mcap_file = path / "run_0.mcap"
    assert sorted(p.name for p in path.iterdir()) == ["metadata.yaml", "run_0.mcap"]
    with open(mcap_file, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        meta_records = {m.name: m.metadata for m in reader.iter_metadata()}
    assert summary.chunk_indexes and {c.compression for c in summary.chunk_indexes} == {"zstd"}
    schemas = {s.name: s for s in summary.schemas.values()}
    assert all(s.encoding == "ros2msg" for s in schemas.values())
    # the documented format, built here by hand from the installed .msg files
    text = lambda pkg, t: (SHARE / pkg / "msg" / f"{t}.msg").read_text()  # noqa: E731
    expected = (text("contgrasp_msgs", "RodState") + f"\n{RULE}\nMSG: std_msgs/Header\n" + text("std_msgs", "Header")
                + f"\n{RULE}\nMSG: builtin_interfaces/Time\n" + text("builtin_interfaces", "Time"))
    assert schemas["contgrasp_msgs/msg/RodState"].data.decode() == expected
    assert schemas["rosgraph_msgs/msg/Clock"].data.decode() == (
        text("rosgraph_msgs", "Clock") + f"\n{RULE}\nMSG: builtin_interfaces/Time\n" + text("builtin_interfaces", "Time"))
    policies = {
        "history": {"keep_last", "keep_all", "system_default", "unknown"},
        "reliability": {"reliable", "best_effort", "system_default", "best_available", "unknown"},
        "durability": {"volatile", "transient_local", "system_default", "best_available", "unknown"},
        "liveliness": {"automatic", "manual_by_topic", "system_default", "best_available", "unknown"},
    }
    by_topic = {}
    for ch in summary.channels.values():
        assert ch.message_encoding == "cdr"
        assert set(ch.metadata) == {"offered_qos_profiles", "topic_type_hash"}
        assert ch.metadata["topic_type_hash"].startswith("RIHS01_") and len(ch.metadata["topic_type_hash"]) == 7 + 64
        profiles = yaml.safe_load(ch.metadata["offered_qos_profiles"])
        assert isinstance(profiles, list) and profiles
        for q in profiles:
            assert list(q) == ["history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
                               "liveliness_lease_duration", "avoid_ros_namespace_conventions"]
            for key, allowed in policies.items():
                assert q[key] in allowed
            for key in ("deadline", "lifespan", "liveliness_lease_duration"):
                assert set(q[key]) == {"sec", "nsec"} and 0 <= q[key]["nsec"] < 10**9
        by_topic[ch.topic] = profiles[0]
    assert by_topic["/contgrasp/object"]["durability"] == "transient_local"  # the latched object
    assert by_topic["/contgrasp/rod_state"]["reliability"] == "reliable"
    assert by_topic["/contgrasp/rod_state"]["durability"] == "volatile"
    inner = yaml.safe_load(meta_records["rosbag2"]["serialized_metadata"])
    outer = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert inner == outer
    assert outer["version"] == 9 and outer["storage_identifier"] == "mcap"
    assert outer["relative_file_paths"] == ["run_0.mcap"]
    assert outer["message_count"] == sum(t["message_count"] for t in outer["topics_with_message_count"])
    run = json.loads(meta_records[RUN_RECORD]["params"])
    assert run["rod_simulator"]["duration"] == 0.1
    counts = {k: json.loads(v) for k, v in meta_records[RECORDER_RECORD].items()}
    assert counts["received"] == counts["written"] == outer["message_count"]


def test_bag_decodes_with_mcap_ros2_rosbags_and_rclpy(graph_bag: tuple[Path, dict]) -> None:
    """Both independent readers decode every message from the embedded schemas (rosbags also
    recomputes each type hash from the definition and checks it against topic_type_hash), and
    rclpy's deserialize/serialize round-trips every message."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rclpy.serialization import deserialize_message, serialize_message
    from rosbags.highlevel import AnyReader

    from contgrasp_ros.plumbing.topics import message_class

    path, summary = graph_bag
    with open(path / "run_0.mcap", "rb") as f:
        decoded = [(c.topic, m) for _, c, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    n = len(decoded)
    assert n == summary["bag"]["messages"]
    rod_states = [m for t, m in decoded if t == "/contgrasp/rod_state"]
    np.testing.assert_array_equal(rod_states[-1].x, summary["final"]["x"])
    with AnyReader([path]) as reader:  # the bag folder: metadata.yaml + the MCAP file
        rb = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in reader.connections}
    assert len(rb) == n
    assert qos["/contgrasp/object"].durability.name == "TRANSIENT_LOCAL"
    assert qos["/contgrasp/rod_state"].reliability.name == "RELIABLE"
    last_rb = [m for t, m in rb if t == "/contgrasp/rod_state"][-1]
    np.testing.assert_array_equal(last_rb.x, summary["final"]["x"])
    for m in iter_raw(open_recording(path)):
        cls = message_class(m.type)
        msg = deserialize_message(m.data, cls)
        again = serialize_message(msg)
        # equal as messages (not bytes: publishers leave CDR alignment padding uninitialised)
        assert deserialize_message(again, cls) == msg, m.topic


def test_bag_info_lists_topics_like_ros2_bag_info(graph_bag: tuple[Path, dict]) -> None:
    path, summary = graph_bag
    proc = subprocess.run([str(BIN / "contgrasp"), "bag", "info", str(path), "--json"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert {t["name"]: t["count"] for t in out["topics"]} == summary["bag"]["topics"]
    assert out["message_count"] == summary["bag"]["messages"]
    text = subprocess.run([str(BIN / "contgrasp"), "bag", "info", str(path)], capture_output=True, text=True, timeout=60).stdout
    assert "Topic: /contgrasp/rod_state | Type: contgrasp_msgs/msg/RodState" in text and "transient_local" in text


# ---------------------------------------------------------------- damage


def _small_bag(path: Path, n: int = 300, chunk_size: int = 4096) -> list[bytes]:
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    w = BagWriter(path, layout="file", chunk_size=chunk_size)
    w.add_topic("/chatter", "std_msgs/msg/String")
    data = [serialize_message(String(data=f"message {i:05d}")) for i in range(n)]
    for i, d in enumerate(data):
        w.write("/chatter", d, 10**9 + i * 10**6)
    w.close()
    return data


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[bytes, list[bytes]]:
    path = tmp_path_factory.mktemp("small") / "small.mcap"
    data = _small_bag(path)
    return path.read_bytes(), data


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(min_value=0, max_value=10**9))
def test_truncated_files_give_a_clear_error_and_recover_a_prefix(small_bag, tmp_path_factory, cut: int) -> None:  # type: ignore[no-untyped-def]
    raw, data = small_bag
    cut = cut % len(raw)
    d = tmp_path_factory.mktemp("cut")
    bad = d / "cut.mcap"
    bad.write_bytes(raw[:cut])
    with pytest.raises(BagError, match="cut.mcap"):
        open_recording(bad)
    if cut >= 8:
        stats = recover(bad, d / "fixed.mcap")
        got = [m.data for m in iter_raw(open_recording(d / "fixed.mcap"))]
        assert got == data[: len(got)] and stats["messages"] == len(got)  # an intact prefix
        assert stats["output_chunks"] == info(open_recording(d / "fixed.mcap"))["chunk_count"]


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(pos=st.integers(min_value=0, max_value=10**9), flip=st.integers(min_value=1, max_value=255))
def test_any_corrupted_byte_is_detected_and_recovery_keeps_the_intact_chunks(small_bag, tmp_path_factory, pos: int, flip: int) -> None:  # type: ignore[no-untyped-def]
    raw, data = small_bag
    pos = pos % len(raw)
    damaged = bytearray(raw)
    damaged[pos] ^= flip
    d = tmp_path_factory.mktemp("flip")
    bad = d / "flip.mcap"
    bad.write_bytes(bytes(damaged))
    with pytest.raises(BagError):
        open_recording(bad)  # every byte is covered by a magic, a length check or a CRC
    if pos >= 8:
        try:
            recover(bad, d / "fixed.mcap")
        except BagError:
            return  # e.g. the header record itself was hit: a clear error is fine
        got = [m.data for m in iter_raw(open_recording(d / "fixed.mcap"))]
        assert set(got) <= set(data)  # whatever is recovered is genuine


def test_recovery_says_what_was_lost_against_the_recordings_own_counts(small_bag, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Against the file's statistics record when it survives, else metadata.yaml's count, else
    "unknown": a file cut in half has lost its statistics and an unknown number of chunks."""
    from io import BytesIO

    from mcap.reader import make_reader

    raw, data = small_bag
    (tmp_path / "whole.mcap").write_bytes(raw)
    whole = recover(tmp_path / "whole.mcap", tmp_path / "w.mcap")
    assert (whole["chunks_lost"], whole["records_lost"], whole["messages_expected"], whole["messages_lost"]) == (0, 0, 300, 0)

    (tmp_path / "half.mcap").write_bytes(raw[: len(raw) // 2])
    half = recover(tmp_path / "half.mcap", tmp_path / "h.mcap")
    assert 0 < half["messages"] < 300 and half["truncated"]
    assert (half["chunks_lost"], half["records_lost"], half["messages_expected"], half["messages_lost"]) == ("unknown",) * 4

    chunk = make_reader(BytesIO(raw)).get_summary().chunk_indexes[1]  # (the summary survives a damaged chunk)
    flipped = bytearray(raw)
    flipped[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    (tmp_path / "flipped.mcap").write_bytes(bytes(flipped))
    hit = recover(tmp_path / "flipped.mcap", tmp_path / "f.mcap")
    assert (hit["chunks_lost"], hit["records_lost"], hit["messages_expected"]) == (1, 0, 300)
    assert hit["messages_lost"] == 300 - hit["messages"] > 0

    w = BagWriter(tmp_path / "bag", chunk_size=4096)  # a bag folder: metadata.yaml lists each file's messages
    w.add_topic("/chatter", "std_msgs/msg/String")
    for i, d in enumerate(data):
        w.write("/chatter", d, 10**9 + i * 10**6)
    w.close()
    (mcap_file,) = (tmp_path / "bag").glob("*.mcap")
    mcap_file.write_bytes(mcap_file.read_bytes()[: mcap_file.stat().st_size // 2])
    folder = recover(tmp_path / "bag", tmp_path / "b")
    assert (folder["chunks_lost"], folder["messages_expected"]) == ("unknown", 300)
    assert folder["messages_lost"] == 300 - folder["messages"] > 0


def test_recover_refuses_an_output_it_cannot_create_before_reading(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``bag recover IN OUT``: an OUT that cannot be created is bad input (exit 2, one line naming
    the recovered recording, not "record"), found by a probe file before the input is read; it
    was an exit 1 from the writer after the scan had begun."""
    from contgrasp_core.cli import main

    cut = tmp_path / "cut.mcap"
    cut.write_bytes((Path(__file__).resolve().parents[1] / "bags" / "paper_grasp.mcap").read_bytes()[:300_000])
    (tmp_path / "file").write_text("x")
    for out, why in (("/proc/contgrasp-none/o.mcap", "cannot create a file in /proc (No such file or directory)"),
                     (str(tmp_path / "file" / "o.mcap"), f"{tmp_path / 'file'} is not a directory"),
                     (str(tmp_path / "file"), "already exists: give a new path")):
        capsys.readouterr()
        assert main(["bag", "recover", str(cut), out]) == 2, out
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.splitlines() == [
            f"contgrasp bag recover: error: the recovered recording {out}"
            + (" " if why.startswith("already") else ": ") + why]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut.mcap", "file"]


def test_unwritable_outputs_are_clear_errors(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(BagError, match="cannot record"):
        BagWriter(blocker / "bag")
    taken = tmp_path / "taken.mcap"
    taken.write_bytes(b"")
    with pytest.raises(BagError, match="already exists"):
        BagWriter(taken, layout="file")

    class Full:  # a stream whose disk is full
        def write(self, b: bytes) -> int:
            raise OSError(28, "No space left on device")

    w = BagWriter(tmp_path / "ok.mcap", layout="file", chunk_size=1024)
    w.add_topic("/chatter", "std_msgs/msg/String")
    w._mcap._Writer__stream = Full()  # noqa: SLF001 - simulate ENOSPC below the MCAP writer
    with pytest.raises(BagError, match="No space left"):
        for i in range(200):
            w.write("/chatter", b"\x00\x01\x00\x00" + bytes(64), i)


# ---------------------------------------------------------------- split bags


def _chatter(n: int, noise: int = 0) -> list[bytes]:
    """Serialized std_msgs/String messages, with ``noise`` random bytes (as hex) each."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    return [serialize_message(String(data=f"message {i:05d} " + os.urandom(noise).hex())) for i in range(n)]


def _write_split(path: Path, data: list[bytes], period_ns: int, close: bool = True, **split: float) -> BagWriter:
    w = BagWriter(path, chunk_size=4096, **split)
    w.records[RUN_RECORD] = {"run": "split"}
    w.add_topic("/chatter", "std_msgs/msg/String")
    for i, d in enumerate(data):
        w.write("/chatter", d, 10**9 + i * period_ns)
    if close:
        w.close()
    else:
        w.flush()
    return w


def test_split_bag_folder_by_duration_is_a_rosbag2_multi_file_bag(tmp_path: Path) -> None:
    """--max-bag-duration: files NAME_0, NAME_1, ... each spanning less than the period, each a
    complete MCAP file on its own; metadata.yaml lists them in order; our reader and rosbags
    read the folder as one recording with every message in order."""
    from rosbags.highlevel import AnyReader

    data = _chatter(300)
    _write_split(tmp_path / "bag", data, 10**7, max_bag_duration=1.0)  # 100 messages per second, 3 s
    meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    names = [f"bag_{k}.mcap" for k in range(3)]
    assert meta["relative_file_paths"] == names and meta["message_count"] == 300
    assert [f["message_count"] for f in meta["files"]] == [100, 100, 100]
    assert [f["starting_time"]["nanoseconds_since_epoch"] for f in meta["files"]] == [10**9, 2 * 10**9, 3 * 10**9]
    assert meta["topics_with_message_count"][0]["message_count"] == 300
    for k, name in enumerate(names):  # each file stands on its own (summary, schema, channel, records)
        rec = open_recording(tmp_path / "bag" / name)
        assert [m.data for m in iter_raw(rec)] == data[100 * k : 100 * (k + 1)]
        assert rec.metadata_records()[RUN_RECORD] == {"run": "split"} and "rosbag2" in rec.metadata_records()
    assert [m.data for m in iter_raw(open_recording(tmp_path / "bag"))] == data
    with AnyReader([tmp_path / "bag"]) as reader:
        got = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()]
    assert got == [f"message {i:05d} " for i in range(300)]


def test_split_bag_folder_by_size(tmp_path: Path) -> None:
    from contgrasp_ros.bag.writer import MIN_BAG_SIZE

    data = _chatter(600, noise=500)  # 600 kB of hex digits, ~half of it after zstd: several 64 kB files
    w = _write_split(tmp_path / "bag", data, 10**6, max_bag_size=MIN_BAG_SIZE)
    sizes = [(tmp_path / "bag" / f.name).stat().st_size for f in w.files]
    assert len(sizes) >= 2
    assert all(sz < MIN_BAG_SIZE + 8 * 4096 for sz in sizes[:-1])  # split at the first chunk past the size
    assert [m.data for m in iter_raw(open_recording(tmp_path / "bag"))] == data


def test_split_bag_without_metadata_reads_files_in_numeric_order_and_recovers(tmp_path: Path) -> None:
    """A killed recorder leaves finished files and an incomplete last one, no metadata.yaml:
    opening names the incomplete file; files sort NAME_2 < NAME_10; recovery keeps everything
    that was flushed, in order."""
    data = _chatter(1200)
    w = _write_split(tmp_path / "bag", data, 10**7, close=False, max_bag_duration=1.0)  # 12 files, last one open
    assert len(w.files) == 12 and not (tmp_path / "bag" / "metadata.yaml").exists()
    with pytest.raises(BagError, match="bag_11.mcap is incomplete"):
        open_recording(tmp_path / "bag")
    stats = recover(tmp_path / "bag", tmp_path / "fixed")
    got = [m.data for m in iter_raw(open_recording(tmp_path / "fixed"))]
    assert got == data and stats["messages"] == 1200  # flushed: the open file's chunks are on disk too
    (tmp_path / "bag" / "bag_11.mcap").unlink()  # the finished files alone are read file by file, in order
    assert [m.data for m in iter_raw(open_recording(tmp_path / "bag"))] == data[:1100]


def test_split_options_are_validated(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="max_bag_size"):
        BagWriter(tmp_path / "a", max_bag_size=1000)
    with pytest.raises(BagError, match="max_bag_duration"):
        BagWriter(tmp_path / "b", max_bag_duration=float("nan"))
    with pytest.raises(BagError, match="cannot be split"):
        BagWriter(tmp_path / "c.mcap", layout="file", max_bag_duration=1.0)


# ---------------------------------------------------------------- recorder processes


PUBLISHER = """
import sys, time, rclpy
from contgrasp_msgs.msg import RodState
from std_msgs.msg import String
from contgrasp_ros.plumbing import qos
rclpy.init()
node = rclpy.create_node("test_publisher")
pub = node.create_publisher(RodState, "/contgrasp/rod_state", qos.STREAM)
n, late_at = int(sys.argv[1]), int(sys.argv[2])
while pub.get_subscription_count() < 1:
    rclpy.spin_once(node, timeout_sec=0.05)
late = None
for k in range(n):
    msg = RodState(step=k, s=[0.0, 1.0], x=[float(k), 0.0], y=[0.0, 0.0], theta=[0.0, 0.0])
    msg.header.stamp.sec, msg.header.stamp.nanosec = k // 1000, (k % 1000) * 1_000_000
    pub.publish(msg)
    if k == late_at:
        late = node.create_publisher(String, "/late_topic", qos.STREAM)
    if late is not None and late.get_subscription_count() > 0:
        late.publish(String(data=f"late {k}"))
    time.sleep(0.002)
    print(k, flush=True)
time.sleep(1.0)
"""


def _recorder(out: Path, env: dict[str, str], *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "contgrasp_ros.nodes.mcap_recorder", "--ros-args", "-p", f"output:={out}", *extra],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )


def test_recorder_picks_up_new_topics_and_survives_sigkill(tmp_path: Path) -> None:
    """A topic that appears mid-run is recorded; a recorder killed with SIGKILL leaves an
    incomplete file (clear error) from which every complete chunk is recovered, in order."""
    env = ros_env(fresh_domain_id())
    rec = _recorder(tmp_path / "bag", env, "-p", "flush_period:=0.1", "-p", "chunk_size:=4096",
                    "-p", "decimate_topics:=['/none']", "-p", "decimate_period:=0.0")
    pub = subprocess.Popen([sys.executable, "-c", PUBLISHER, "1500", "100"], env=env, stdout=subprocess.PIPE, text=True)
    try:
        published = -1
        assert pub.stdout is not None
        while published < 1200:
            line = pub.stdout.readline()
            assert line, "publisher ended early"
            published = int(line.split()[0])
        time.sleep(0.3)  # > flush_period: what was received is in complete chunks now
        rec.send_signal(signal.SIGKILL)
        rec.wait(timeout=30)
    finally:
        for p in (pub, rec):
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)
    bag_file = tmp_path / "bag" / "bag_0.mcap"
    assert not (tmp_path / "bag" / "metadata.yaml").exists()
    with pytest.raises(BagError, match="incomplete"):
        open_recording(tmp_path / "bag")
    fixed = tmp_path / "fixed"
    proc = subprocess.run([str(BIN / "contgrasp"), "bag", "recover", str(bag_file), str(fixed), "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["truncated"] in (True, False)
    rec2 = open_recording(fixed)  # a finished bag folder with metadata.yaml
    steps = [m.step for _, m in iter_decoded(rec2, ["/contgrasp/rod_state"])]
    assert steps == list(range(len(steps))) and len(steps) >= 1000  # a gap-free prefix, nearly all of it
    late = [m.data for _, m in iter_decoded(rec2, ["/late_topic"])]
    assert late and all(s.startswith("late ") for s in late)
    assert {t["name"] for t in info(rec2)["topics"]} >= {"/contgrasp/rod_state", "/late_topic"}


def test_recorder_with_unwritable_output_exits_1_with_the_reason(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    proc = _recorder(blocker / "bag", ros_env(fresh_domain_id()))
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 1 and "cannot record" in out


def test_replay_reproduces_sequence_and_timing(tmp_path: Path) -> None:
    """`contgrasp replay --rate 2` republishes a recording; a second recorder sees the same
    messages in the same order, spaced by the recorded intervals / 2. (--wait-for-subscribers:
    the recorder subscribes only once it has seen the replay's publishers; a fixed 2 s delay lost
    the first 122 messages in CI's 3.12 leg.)"""
    from rclpy.serialization import serialize_message

    from contgrasp_msgs.msg import ObjectBoundary, RodState

    src = tmp_path / "src.mcap"
    w = BagWriter(src, layout="file")
    w.add_topic("/contgrasp/object", "contgrasp_msgs/msg/ObjectBoundary",
                [{"history": "keep_last", "depth": 1, "reliability": "reliable", "durability": "transient_local"}])
    w.add_topic("/contgrasp/rod_state", "contgrasp_msgs/msg/RodState")
    t0 = 1_700_000_000 * 10**9
    w.write("/contgrasp/object", serialize_message(ObjectBoundary(kind="circle", x=[1.0, 2.0], y=[3.0, 4.0])), t0)
    gaps = np.r_[0.0, np.cumsum(np.random.default_rng(3).uniform(0.002, 0.03, 199))]
    for k, g in enumerate(gaps):
        w.write("/contgrasp/rod_state", serialize_message(RodState(step=k, x=[float(k)])), t0 + 10**8 + int(g * 1e9))
    w.close()
    env = ros_env(fresh_domain_id())
    rec = _recorder(tmp_path / "copy", env, "-p", "topics:=['/contgrasp/rod_state','/contgrasp/object']")
    try:
        time.sleep(2.0)
        proc = subprocess.run([str(BIN / "contgrasp"), "replay", str(src), "--rate", "2", "--delay", "1",
                               "--wait-for-subscribers", "--json"],
                              capture_output=True, text=True, timeout=120, env=env)
        assert proc.returncode == 0, proc.stderr
        assert json.loads(proc.stdout)["published"] == 201
        time.sleep(1.0)
    finally:
        rec.send_signal(signal.SIGINT)
        rec.wait(timeout=30)
    copy = open_recording(tmp_path / "copy")
    got = list(iter_raw(copy, ["/contgrasp/rod_state"]))
    orig = list(iter_raw(open_recording(src), ["/contgrasp/rod_state"]))
    assert len(got) == len(orig), (len(got), len(orig), [m.data[:40] for m in got[:2]])
    assert [m.data for m in got] == [m.data for m in orig]
    assert [m.data for m in iter_raw(copy, ["/contgrasp/object"])] == [m.data for m in iter_raw(open_recording(src), ["/contgrasp/object"])]
    t_got = np.array([m.log_time_ns for m in got]) * 1e-9
    t_orig = np.array([m.log_time_ns for m in orig]) * 1e-9
    err = (t_got - t_got[0]) - (t_orig - t_orig[0]) / 2.0
    assert np.median(np.abs(err)) < 0.01 and np.max(np.abs(err)) < 0.1, err


def test_shipped_sample_analysis_reproduces_its_summary() -> None:
    """`contgrasp analyze bags/paper_grasp.mcap --json` gives back what the launcher printed when
    the sample was recorded, and the quality recomputed from the recorded rod states matches the
    recorded quality topic to 1e-9."""
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([str(BIN / "contgrasp"), "analyze", str(root / "bags" / "paper_grasp.mcap"), "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    made = json.loads((root / "bags" / "paper_grasp.summary.json").read_text())
    for key in ("settled", "settle_time_s", "sim_time_s", "steps", "missed_deadlines", "max_penetration", "final_quality",
                "mean_abs_rho_ratio_minus_1_contact", "mean_abs_alpha_minus_half_pi_contact"):
        assert got[key] == made[key], key
    for key in ("s", "x", "y", "theta"):
        np.testing.assert_allclose(got["final"][key], made["final"][key], rtol=0, atol=1e-12)
    assert got["max_recompute_error"] <= 1e-9
    assert got["recomputed_pairs"]["quality"] == made["bag"]["topics"]["/contgrasp/quality"]
    assert {t["name"]: t["count"] for t in got["topics"]} == made["bag"]["topics"]


def test_recorder_counts_messages_lost_before_it_from_sequence_gaps(ros_context, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Gaps in a single publisher's sequence numbers are reported as lost in transport; a
    restarted publisher (numbers start over) or several publishers are not counted as loss."""
    from types import SimpleNamespace

    from rclpy.parameter import Parameter

    from contgrasp_ros.nodes.mcap_recorder import McapRecorder

    node = McapRecorder(context=ros_context, parameter_overrides=[Parameter("output", value=str(tmp_path / "bag"))])
    try:
        node.writer.add_topic("/t", "std_msgs/msg/String")
        node.received["/t"], node.lost_in_transport["/t"] = 0, 0
        payload = b"\x00\x01\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00"

        def receive(*seqs: int) -> None:
            for seq in seqs:
                node.on_message("/t", payload, {"publication_sequence_number": seq, "source_timestamp": 1})

        receive(1, 5)  # no publisher matched yet: not checked
        node.on_matched("/t", SimpleNamespace(current_count=1))
        receive(1, 2, 5, 6, 1, 2, 4)  # 3, 4 lost; restart; 3 lost
        assert node.counts()["lost_in_transport"] == 3
        node.on_matched("/t", SimpleNamespace(current_count=2))
        receive(10, 20, 11)  # two publishers interleaved
        node.on_matched("/t", SimpleNamespace(current_count=1))
        receive(30, 31, 33)  # one publisher again: counted from its next message
        c = node.counts()
        assert c["lost_in_transport"] == 4 and c["received"] == c["written"] == 15
    finally:
        node.destroy_node()
    assert json.loads(open_recording(tmp_path / "bag").metadata_records()[RECORDER_RECORD]["lost_in_transport"]) == 4


def test_recorder_refuses_an_invalid_sequence_check_regex(ros_context, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from rclpy.parameter import Parameter

    from contgrasp_core.errors import InvalidParameterError
    from contgrasp_ros.nodes.mcap_recorder import McapRecorder

    with pytest.raises(InvalidParameterError, match="invalid regular expression"):
        McapRecorder(context=ros_context, parameter_overrides=[Parameter("output", value=str(tmp_path / "bag")),
                                                               Parameter("sequence_check_exclude_regex", value="(")])


@pytest.mark.parametrize(("params", "why"), [
    ({"max_bag_size": 1000}, "max_bag_size must be 0"),
    ({"max_bag_duration": -1.0}, "max_bag_duration"),
    ({"layout": "file", "max_bag_duration": 10.0}, "use layout 'folder'"),
])
def test_recorder_refuses_invalid_split_options(ros_context, tmp_path: Path, params: dict, why: str) -> None:  # type: ignore[no-untyped-def]
    import rclpy
    from rclpy.parameter import Parameter

    from contgrasp_core.errors import InvalidParameterError
    from contgrasp_ros.nodes.mcap_recorder import McapRecorder

    out = tmp_path / ("bag.mcap" if params.get("layout") == "file" else "bag")
    with pytest.raises((InvalidParameterError, rclpy.exceptions.ParameterException), match=why):
        McapRecorder(context=ros_context, parameter_overrides=[Parameter("output", value=str(out)),
                                                               *(Parameter(k, value=v) for k, v in params.items())])
    assert not out.exists()  # refused before anything was created


def test_recorder_does_not_count_interleaved_publishers_as_loss(ros_context, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Real publishers: a second publisher joining a recorded topic (and every node's
    /parameter_events) mixes sequence numbers; none of it is reported as lost."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from contgrasp_ros.nodes.mcap_recorder import McapRecorder

    rec = McapRecorder(context=ros_context, parameter_overrides=[Parameter("output", value=str(tmp_path / "bag"))])
    a, b = Node("pub_a", context=ros_context), Node("pub_b", context=ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (rec, a, b):
        ex.add_node(n)
    try:
        pa = a.create_publisher(String, "/mixed", 100)

        def spin_until(cond, timeout: float = 10.0) -> None:  # type: ignore[no-untyped-def]
            end = time.monotonic() + timeout
            while not cond() and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.02)
            assert cond()

        spin_until(lambda: "/mixed" in rec._subs and pa.get_subscription_count() == 1)
        for i in range(20):
            pa.publish(String(data=f"a{i}"))
        spin_until(lambda: rec.received["/mixed"] == 20)
        pb = b.create_publisher(String, "/mixed", 100)
        spin_until(lambda: pb.get_subscription_count() == 1)
        for i in range(30):  # a is at 20, b at 0: interleaved numbers jump both ways
            (pa if i % 3 == 0 else pb).publish(String(data=str(i)))
            if i % 5 == 0:  # more /parameter_events, from several nodes
                (a if i % 2 else b).declare_parameter(f"p{i}", i)
        spin_until(lambda: rec.received["/mixed"] == 50)
        c = rec.counts()
        assert c["lost_in_transport"] == 0, c["lost_in_transport_per_topic"]
        assert c["received"] == c["written"]
    finally:
        ex.shutdown()
        for n in (a, b, rec):
            n.destroy_node()


def test_replay_window_and_loop(tmp_path: Path) -> None:
    """--start/--end select a log-time window; --loop starts over until interrupted."""
    path = tmp_path / "small.mcap"
    _small_bag(path, n=300)  # one message per ms
    env = ros_env(fresh_domain_id())
    proc = subprocess.run([str(BIN / "contgrasp"), "replay", str(path), "--start", "0.1", "--end", "0.2", "--delay", "0",
                           "--rate", "10", "--json"], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["published"] == 101  # 100 ms .. 200 ms inclusive
    # (a probe hears the loop's passes: Ctrl-C after more than one of them, however slow the
    # replay's start-up; a fixed 4 s once ended it while it was still loading)
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    probe = rclpy.create_node("loop_probe", context=ctx)
    heard: list[str] = []
    probe.create_subscription(String, "/chatter", lambda m: heard.append(m.data), 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(probe)
    loop = subprocess.Popen([str(BIN / "contgrasp"), "replay", str(path), "--loop", "--rate", "5", "--delay", "0", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        end = time.monotonic() + 120
        while len(heard) <= 300 and time.monotonic() < end and loop.poll() is None:
            ex.spin_once(timeout_sec=0.05)
    finally:
        ex.shutdown()
        probe.destroy_node()
        rclpy.shutdown(context=ctx)
    assert len(heard) > 300, len(heard)
    loop.send_signal(signal.SIGINT)
    out, err = loop.communicate(timeout=60)
    assert loop.returncode == 0, err
    assert json.loads(out)["published"] > 300
    bad = subprocess.run([str(BIN / "contgrasp"), "replay", str(path), "--rate", "0"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "rate" in bad.stderr


def test_replay_refuses_a_start_after_the_recordings_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A --start past the last message published nothing and exited 0; now it is bad input
    (exit 2, one line with the recording's length), found before any ROS node is created."""
    from contgrasp_core.cli import main
    from contgrasp_core.errors import InvalidParameterError
    from contgrasp_ros.recordings.replay import replay

    path = tmp_path / "small.mcap"
    _small_bag(path, n=300)  # one message per ms: the last 0.299 s after the first
    why = "--start 5 s is after the recording's end (0.299 s after its first message)"
    with pytest.raises(InvalidParameterError, match=f"^{re.escape(why)}$"):
        replay(path, start=5.0, delay=0.0)
    capsys.readouterr()
    assert main(["replay", str(path), "--start", "5"]) == 2
    assert capsys.readouterr().err.splitlines() == [f"contgrasp replay: error: {why}"]


@contextmanager
def _after_300_states(rec: subprocess.Popen[str], env: dict[str, str]) -> Iterator[None]:
    """Publish 300 rod states to the running recorder ``rec``; the block runs once they are out;
    afterwards nothing of the test is left running."""
    pub = subprocess.Popen([sys.executable, "-c", PUBLISHER, "300", "-1"], env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert pub.stdout is not None
        while int(pub.stdout.readline().split()[0]) < 299:
            pass
        time.sleep(0.5)
        yield
    finally:
        for p in (pub, rec):
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)


def test_recorder_finalises_through_repeated_ctrl_c(tmp_path: Path) -> None:
    """Ctrl-C under ros2 launch reaches a node twice (the terminal's and the one launch forwards):
    later SIGINTs during the clean-up are ignored, so the node exits 0 with no traceback and the
    recording is complete (before: a KeyboardInterrupt traceback mid-clean-up, exit -2)."""
    env = ros_env(fresh_domain_id())
    rec = _recorder(tmp_path / "bag", env)
    with _after_300_states(rec, env):
        for _ in range(20):  # a burst that covers the recorder's clean-up
            if rec.poll() is not None:
                break
            rec.send_signal(signal.SIGINT)
            time.sleep(0.01)
        out, _ = rec.communicate(timeout=30)
    assert rec.returncode == 0 and "Traceback" not in out and "KeyboardInterrupt" not in out, out[-3000:]
    steps = [m.step for _, m in iter_decoded(open_recording(tmp_path / "bag"), ["/contgrasp/rod_state"])]
    assert steps == list(range(300))


def test_recorder_finalises_on_sigterm(tmp_path: Path) -> None:
    """(With a split every 0.2 s: the messages span several files, none lost at the splits.)"""
    env = ros_env(fresh_domain_id())
    rec = _recorder(tmp_path / "bag", env, "-p", "max_bag_duration:=0.2")
    with _after_300_states(rec, env):
        rec.send_signal(signal.SIGTERM)
        assert rec.wait(timeout=30) == 0
    rec_ = open_recording(tmp_path / "bag")
    assert len(rec_.files) >= 3  # 300 messages 2 ms apart (and more) in 0.2 s files
    steps = [m.step for _, m in iter_decoded(rec_, ["/contgrasp/rod_state"])]
    assert steps == list(range(300))


def test_replay_of_a_type_whose_package_is_missing_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    """A recorded type of a message package the ROS layer needs, not installed, is a missing
    dependency (exit 2, naming what to install); another package's (a recording made elsewhere),
    or a type the installed package lacks, fails the replay (exit 1)."""
    from contgrasp_core.errors import MissingDependencyError, RunFailure
    from contgrasp_ros.recordings.replay import _message_class

    monkeypatch.setitem(sys.modules, "rosgraph_msgs", None)
    monkeypatch.setitem(sys.modules, "rosgraph_msgs.msg", None)
    with pytest.raises(MissingDependencyError, match=r"^cannot replay rosgraph_msgs/msg/Clock: needs ROS 2 Jazzy "
                                                     r"\(module 'rosgraph_msgs' is missing\).*contgrasp\[ros,ros-wheels,msgs\]"):
        _message_class("rosgraph_msgs/msg/Clock")
    with pytest.raises(RunFailure, match=r"^cannot replay no_such_msgs/msg/Thing: the message package is not installed"):
        _message_class("no_such_msgs/msg/Thing")
    with pytest.raises(RunFailure, match=r"^cannot replay std_msgs/msg/NoSuchType: the installed message package does not define it"):
        _message_class("std_msgs/msg/NoSuchType")
    proc = subprocess.run([sys.executable, "-c", "import sys; sys.modules['rosgraph_msgs'] = None\n"
                           "from contgrasp_core.cli import main\n"
                           f"sys.exit(main(['replay', {str(Path(__file__).parents[1] / 'bags' / 'paper_grasp.mcap')!r}]))"],
                          capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, ROS_DOMAIN_ID=str(fresh_domain_id())))
    assert proc.returncode == 2 and "contgrasp replay: error: cannot replay rosgraph_msgs/msg/Clock: needs ROS 2 Jazzy" in proc.stderr, proc.stderr
