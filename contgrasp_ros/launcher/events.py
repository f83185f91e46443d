"""The launcher's machine-readable events: JSON lines on a channel of their own.

``contgrasp-launch --events FILE`` (``-`` for stdout, ``fd:N`` for an inherited file descriptor)
writes and flushes one JSON object per line, with ``event`` (its kind) and ``time`` (Unix time,
s): ``domain_id`` (always first), ``started``, ``restarted``, ``exited``, ``resumed`` and
``finished`` (always last). The fields of each kind: docs/cli.md, ``contgrasp-launch``.
Nothing here imports rclpy.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from typing import IO, Any, Protocol

from contgrasp_core.errors import InvalidParameterError, output_error
from contgrasp_core.outputs import check_output

__all__ = ["EVENTS", "EventSink", "EventWriter", "open_events", "parse_event", "read_events"]

EVENTS = ("domain_id", "started", "restarted", "exited", "resumed", "finished")


class EventSink(Protocol):
    """Where the launcher reports an event: ``sink("started", node=..., pid=...)``."""

    def __call__(self, event: str, /, **fields: Any) -> None: ...


class EventWriter:
    """Writes events as JSON lines to ``stream`` (thread-safe; each line flushed)."""

    def __init__(self, stream: IO[str], close: bool = False) -> None:
        self.stream = stream
        self._close = close
        self._lock = threading.Lock()

    def __call__(self, event: str, /, **fields: Any) -> None:
        if event not in EVENTS:
            raise ValueError(f"unknown launcher event {event!r}")
        line = json.dumps({"event": event, "time": time.time(), **fields}, allow_nan=False)
        with self._lock:
            self.stream.write(line + "\n")
            self.stream.flush()

    def close(self) -> None:
        if self._close:
            self.stream.close()


def open_events(target: str) -> EventWriter:
    """The :class:`EventWriter` for ``--events TARGET``: ``-`` (stdout), ``fd:N`` (an open file
    descriptor, e.g. a pipe the caller passed down) or a file path (created or truncated)."""
    if target == "-":
        return EventWriter(sys.stdout)
    if target.startswith("fd:"):
        try:
            fd = int(target[3:])
            return EventWriter(os.fdopen(fd, "w", buffering=1), close=True)
        except (ValueError, OSError) as exc:
            raise InvalidParameterError(f"--events {target}: not an open file descriptor ({exc})") from exc
    path = check_output(target, "--events")  # (a path it cannot create: bad input, exit 2)
    try:
        return EventWriter(open(path, "w", buffering=1), close=True)  # (closed by close())
    except OSError as exc:
        raise output_error(f"the events file {target}", exc) from exc


def parse_event(line: str) -> dict[str, Any]:
    """One event line as a dict; ValueError unless it is a JSON object with a known ``event``."""
    obj = json.loads(line)
    if not isinstance(obj, dict) or obj.get("event") not in EVENTS:
        raise ValueError(f"not a launcher event: {line.strip()!r}")
    return obj


def read_events(lines: Iterable[str]) -> Iterator[dict[str, Any]]:
    """The events of a stream of lines (blank lines skipped)."""
    for line in lines:
        if line.strip():
            yield parse_event(line)
