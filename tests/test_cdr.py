"""The loop's serialized messages (contgrasp_ros.plumbing.cdr) against rclpy's own serializer: what the
codec writes, rclpy reads as the message it was made from; what rclpy writes, the codec reads
as that message. Malformed bytes are refused with a reason, and a node that gets them counts the
drop and goes on."""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from contgrasp_core.boundary import circle  # noqa: E402
from contgrasp_msgs.msg import ContactState, CoupleControl, ObjectBoundary, RodState  # noqa: E402
from contgrasp_ros.plumbing.cdr import Codec  # noqa: E402
from contgrasp_ros.plumbing.convert import MessageError, boundary_to_msg  # noqa: E402

from conftest import Sink  # noqa: E402

TYPES = (RodState, ContactState, CoupleControl)
floats = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def messages(draw: Any, msg_type: Any) -> tuple[dict[str, Any], Any]:
    """Field values (numpy arrays) and the typed message with the same values."""
    values: dict[str, Any] = {}
    for name, kind in Codec(msg_type).fields:
        n = draw(st.integers(0, 12))
        if kind == "header":
            values[name] = Header(stamp=Time(sec=draw(st.integers(-2**31, 2**31 - 1)), nanosec=draw(st.integers(0, 2**32 - 1))),
                                  frame_id=draw(st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=9)))  # (C strings)
        elif kind == "uint64":
            values[name] = draw(st.integers(0, 2**64 - 1))
        elif kind == "double":
            values[name] = draw(floats)
        elif kind == "bool":
            values[name] = draw(st.booleans())
        elif kind == "float64[]":
            values[name] = np.array(draw(st.lists(floats, min_size=n, max_size=n)), dtype=float)
        else:
            values[name] = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=bool)
    typed = msg_type(**{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in values.items()})
    return values, typed


def same(a: Any, b: Any) -> bool:
    """Equal field by field, NaN equal to NaN (bit patterns aside)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a == b))


def fields_equal(view: Any, typed: Any, codec: Codec) -> None:
    for name, kind in codec.fields:
        got, want = getattr(view, name), getattr(typed, name)
        if kind == "header":
            assert (got.stamp.sec, got.stamp.nanosec, got.frame_id) == (want.stamp.sec, want.stamp.nanosec, want.frame_id)
        elif kind in ("float64[]", "bool[]"):
            assert same(got, want), name
        else:
            assert same(got, want), name


@pytest.mark.parametrize("msg_type", TYPES, ids=lambda t: t.__name__)
def test_rclpy_reads_what_the_codec_writes_and_the_codec_reads_what_rclpy_writes(msg_type: Any) -> None:
    codec = Codec(msg_type)

    @settings(max_examples=150, deadline=None)
    @given(messages(msg_type))
    def prop(msg: tuple[dict[str, Any], Any]) -> None:
        values, typed = msg
        back = deserialize_message(codec.encode(values), msg_type)
        fields_equal(back, typed, codec)
        view = codec.decode(serialize_message(typed))
        fields_equal(view, typed, codec)
        for name, kind in codec.fields:  # arrays ready for the compiled kernels: writable, aligned, native
            if kind == "float64[]":
                arr = getattr(view, name)
                assert arr.flags.writeable and arr.flags.aligned and arr.dtype == np.float64 and arr.dtype.isnative

    prop()


def test_a_big_endian_message_is_read() -> None:
    """CDR big endian (encapsulation 00 00), written by hand."""
    payload = struct.pack(">iII", 7, 5, 6) + b"world\x00" + b"\x00" * 6  # header, padded to 24 (step is 8-aligned)
    payload += struct.pack(">Q", 42)
    payload += struct.pack(">I", 2) + b"\x00" * 4 + struct.pack(">2d", 0.5, 1.5)  # s (count at 32, values 8-aligned at 40)
    payload += struct.pack(">I", 2) + b"\x00" * 4 + struct.pack(">2d", -3.0, 4.25)  # u
    payload += struct.pack(">4I", 0, 0, 0, 0)  # the four empty expansion fields
    payload += struct.pack(">I", 0) + b"\x00" * 4 + struct.pack(">d", 2.5) + b"\x01"  # kappa_ref (empty at 96), hold_gain (104), transition
    msg = Codec(CoupleControl).decode(b"\x00\x00\x00\x00" + payload)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id, msg.step) == (7, 5, "world", 42)
    assert msg.kappa_ref.size == 0 and msg.hold_gain == 2.5 and msg.transition is True
    assert msg.s.tolist() == [0.5, 1.5] and msg.u.tolist() == [-3.0, 4.25] and msg.du_dalpha.size == 0
    assert deserialize_message(Codec(CoupleControl).encode({"s": msg.s, "u": msg.u, "step": 42}), CoupleControl).u.tolist() == [-3.0, 4.25]


def test_malformed_bytes_are_refused_with_a_reason() -> None:
    codec = Codec(ContactState)
    a = np.linspace(0.0, 1.0, 5)
    data = codec.encode({"header": Header(frame_id="world"), "step": 3, "s": a, "rho": a, "alpha": a, "delta": a, "s_o": a,
                         "shadow_x": a, "shadow_y": a, "in_contact": a > 0.5, "contact_tolerance": 0.001})
    assert codec.decode(data).contact_tolerance == 0.001
    for cut in range(len(data)):  # every message cut short
        with pytest.raises(MessageError) as err:
            codec.decode(data[:cut])
        assert err.value.reason == "bad encoding"
    # payload layout: stamp 0-8, frame_id length 8-12, "world\0" 12-18, step 24-32, count of 's' 32-36, its values from 40
    bad = {
        "a count beyond the end": data[:4 + 32] + struct.pack("<I", 2**32 - 1) + data[4 + 36:],
        "another encapsulation (XCDR2)": b"\x00\x07\x00\x00" + data[4:],
        "a frame_id without its NUL": data[:4 + 12 + 5] + b"X" + data[4 + 18:],
        "a frame_id that is not UTF-8": data[:4 + 12] + b"\xff\xfe\xfd\xfc\xfb" + data[4 + 17:],
    }
    for what, raw in bad.items():
        with pytest.raises(MessageError) as err:
            codec.decode(raw)
        assert err.value.reason == "bad encoding", what


def test_only_the_supported_field_types() -> None:
    with pytest.raises(TypeError, match="ObjectBoundary"):
        Codec(ObjectBoundary)  # (strings and string arrays)


def test_the_loop_nodes_count_undecodable_messages_and_go_on(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor
    from contgrasp_ros.nodes.grasp_controller import GraspController

    sensor = make(BoundarySensor)
    sensor.pub = Sink(ContactState)
    sensor.object.on_object(boundary_to_msg(circle(0.025, (0.08, 0.08)), Header()))
    controller = make(GraspController, n_elements=4)
    controller.pub = Sink(CoupleControl)
    s = np.linspace(0.0, 0.2, 5)
    state = RodState(step=1, s=s.tolist(), x=s.tolist(), y=[0.0] * 5, theta=[0.0] * 5, radius=[0.01] * 5)
    state.header.stamp.sec = 1
    for garbage in (b"", b"\x00\x01\x00\x00", serialize_message(state)[:40]):
        sensor.on_rod_state(garbage)
        controller.on_contact(garbage)
    assert sensor.drops.counts == {"/contgrasp/rod_state: bad encoding": 3}
    assert controller.drops.counts == {"/contgrasp/contact: bad encoding": 3}
    sensor.on_rod_state(serialize_message(state))  # and the next good message is sensed and answered
    assert [m.step for m in sensor.pub.msgs] == [1]
    controller.on_contact(serialize_message(sensor.pub.msgs[0]))
    assert [m.step for m in controller.pub.msgs] == [1] and len(controller.pub.msgs[0].u) == 4
