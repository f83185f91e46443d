"""The loop's messages as CDR bytes, straight from and into numpy arrays.

The loop's nodes publish serialized messages and subscribe with ``raw=True``; :class:`Codec`
writes and reads the bytes (OMG CDR version 1, what rmw_fastrtps sends) with numpy, for messages
of ``std_msgs/Header``, ``uint64``, ``double``, ``boolean`` and sequences of double and boolean
fields (the loop's three types). :meth:`Codec.decode` gives a :class:`MessageView` that
:mod:`contgrasp_ros.plumbing.convert`'s readers validate like a typed message; bytes that are not
a message of the type raise :class:`~contgrasp_ros.plumbing.convert.MessageError` (``"bad
encoding"``). Nothing changes on the wire (tests/test_cdr.py). docs/ros.md, "Serialized messages
on the loop".
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from typing import Any

import numpy as np

from contgrasp_ros.plumbing.convert import MessageError

__all__ = ["Codec", "MessageView", "Stamp", "HeaderView"]

_ENCAPSULATION_LE = b"\x00\x01\x00\x00"
_ENCAPSULATION_BE = b"\x00\x00\x00\x00"
_KINDS = {"std_msgs/Header": "header", "uint64": "uint64", "double": "double", "boolean": "bool",
          "sequence<double>": "float64[]", "sequence<boolean>": "bool[]"}
_PAD = tuple(b"\x00" * n for n in range(8))


class Stamp:
    """``builtin_interfaces/Time`` of a decoded header."""

    __slots__ = ("sec", "nanosec")

    def __init__(self, sec: int = 0, nanosec: int = 0) -> None:
        self.sec, self.nanosec = sec, nanosec


class HeaderView:
    """``std_msgs/Header`` of a decoded message."""

    __slots__ = ("stamp", "frame_id")

    def __init__(self, stamp: Stamp, frame_id: str) -> None:
        self.stamp, self.frame_id = stamp, frame_id


class MessageView:
    """A decoded message: its fields as attributes (subclassed per type by :class:`Codec`, named
    after the type, so errors name it as they name a typed message)."""

    __slots__ = ()

    def __repr__(self) -> str:
        names: tuple[str, ...] = self.__slots__
        return f"{type(self).__name__}({', '.join(f'{k}={getattr(self, k)!r}' for k in names)})"


class Codec:
    """Encodes and decodes the CDR form of one message type (a rosidl message class)."""

    def __init__(self, msg_type: Any) -> None:
        fields: Mapping[str, str] = msg_type.get_fields_and_field_types()
        unsupported = {name: t for name, t in fields.items() if t not in _KINDS}
        if unsupported:
            raise TypeError(f"{msg_type.__name__}: Codec supports {', '.join(_KINDS)} fields, not {unsupported}")
        self.msg_type = msg_type
        self.fields = tuple((name, _KINDS[t]) for name, t in fields.items())
        self.view_type = type(msg_type.__name__, (MessageView,), {"__slots__": tuple(fields)})

    # ------------------------------------------------------------------ encode
    def encode(self, values: Mapping[str, Any]) -> bytes:
        """The serialized message of ``values`` (field name -> value; missing fields take the
        message's defaults: zero, empty, a zero header). A header is anything with
        ``stamp.sec``, ``stamp.nanosec`` and ``frame_id`` (a std_msgs Header, a :class:`HeaderView`);
        array fields take anything numpy reads as a 1-D float64 (bool) array."""
        parts: list[bytes] = [_ENCAPSULATION_LE]
        offset = 0  # (payload offset: counted after the encapsulation header)
        for name, kind in self.fields:
            value = values.get(name)
            if kind == "header":
                sec, nanosec, frame = (0, 0, "") if value is None else (value.stamp.sec, value.stamp.nanosec, value.frame_id)
                text = frame.encode() + b"\x00"
                chunk = _PAD[-offset % 4] + struct.pack("<iII", int(sec), int(nanosec), len(text)) + text
            elif kind == "uint64":
                chunk = _PAD[-offset % 8] + struct.pack("<Q", int(value or 0))
            elif kind == "double":
                chunk = _PAD[-offset % 8] + struct.pack("<d", float(value or 0.0))
            elif kind == "bool":
                chunk = b"\x01" if value else b"\x00"
            else:
                data: np.ndarray = np.ascontiguousarray(() if value is None else value, dtype=np.float64 if kind == "float64[]" else np.bool_)
                if data.ndim != 1:
                    raise ValueError(f"{self.msg_type.__name__}.{name}: a 1-D array, got shape {data.shape}")
                chunk = _PAD[-offset % 4] + struct.pack("<I", len(data))
                if len(data) and kind == "float64[]":
                    chunk += _PAD[-(offset + len(chunk)) % 8] + data.astype("<f8", copy=False).tobytes()
                elif len(data):
                    chunk += data.tobytes()
            parts.append(chunk)
            offset += len(chunk)
        return b"".join(parts)

    # ------------------------------------------------------------------ decode
    def message(self, data: Any) -> Any:
        """What a node's callback got, as a message: serialized bytes (its ``raw=True``
        subscription) decoded, a typed message (a direct call) as it is."""
        return self.decode(data) if isinstance(data, bytes) else data

    def decode(self, data: bytes) -> Any:
        """The message in ``data`` (its serialized form, as a ``raw=True`` subscription gets it): a
        :class:`MessageView` (typed Any: its fields are attributes made per message type)."""
        head = bytes(data[:4])
        if head == _ENCAPSULATION_LE:
            order = "<"
        elif head == _ENCAPSULATION_BE:
            order = ">"
        else:
            raise MessageError(f"{self.msg_type.__name__}: not a CDR message (encapsulation {head.hex() or 'missing'})",
                               reason="bad encoding")
        size = len(data) - 4
        # the payload in 8-byte aligned, writable memory: its arrays are used in place
        words = np.empty((size + 7) // 8, dtype=np.float64)
        buf = words.view(np.uint8)
        buf[:size] = np.frombuffer(data, dtype=np.uint8, offset=4)
        raw = buf.data[:size]  # (struct reads the counts and scalars from it, and fails past its end)
        if order == ">":
            words = words.byteswap()  # (whole words: the float64 arrays, which start on 8-byte offsets)
        view = self.view_type()
        offset = 0
        name = ""
        try:
            for name, kind in self.fields:
                if kind == "header":
                    offset += -offset % 4
                    sec, nanosec, length = struct.unpack_from(order + "iII", raw, offset)
                    end = offset + 12 + length
                    if length < 1 or end > size or buf[end - 1] != 0:
                        raise MessageError(f"{self.msg_type.__name__}: field '{name}': frame_id is not a terminated string",
                                           reason="bad encoding")
                    setattr(view, name, HeaderView(Stamp(sec, nanosec), bytes(buf[offset + 12:end - 1]).decode()))
                    offset = end
                elif kind == "uint64" or kind == "double":
                    offset += -offset % 8
                    (value,) = struct.unpack_from(order + ("Q" if kind == "uint64" else "d"), raw, offset)
                    setattr(view, name, value)
                    offset += 8
                elif kind == "bool":
                    (value,) = struct.unpack_from("?", raw, offset)  # (a byte: no alignment, no order)
                    setattr(view, name, value)
                    offset += 1
                else:
                    offset += -offset % 4
                    (count,) = struct.unpack_from(order + "I", raw, offset)
                    offset += 4
                    if kind == "float64[]":
                        if count:
                            offset += -offset % 8
                        end = offset + 8 * count
                        if end > size:
                            raise struct.error("past the end")
                        setattr(view, name, words[offset // 8:end // 8])
                    else:
                        end = offset + count
                        if end > size:
                            raise struct.error("past the end")
                        setattr(view, name, buf[offset:end] != 0)
                    offset = end
        except struct.error as exc:
            raise MessageError(f"{self.msg_type.__name__}: the message ends inside field '{name}' ({size} bytes)",
                               reason="bad encoding") from exc
        except UnicodeDecodeError as exc:
            raise MessageError(f"{self.msg_type.__name__}: frame_id is not UTF-8 ({exc})", reason="bad encoding") from exc
        return view  # (bytes after the last field are ignored, as rmw_fastrtps's own deserializer does)
