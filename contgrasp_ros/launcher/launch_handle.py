"""Run ``contgrasp-launch`` in the background and follow it: child pids, log lines, result.

Used by the fault-injection tests and the soak benchmark (and handy for scripting runs): the
launcher writes its events (:mod:`contgrasp_ros.launcher.events`: each node process it starts, with its
pid, exits, resumes, the end) as JSON lines to a pipe it inherits (``--events fd:N``), and its
human-readable log to stderr; :class:`LaunchHandle` reads both in threads, so callers can wait
for an event or a log line, signal one node by its pid, and collect the JSON summary at the end.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from contgrasp_ros.launcher.events import parse_event

__all__ = ["LaunchHandle"]


class LaunchHandle:
    """``contgrasp-launch --json --events fd:N ARGS`` as a child process with its events and
    stderr followed: ``events`` (every event so far, as dicts), ``pids`` (each node's latest
    pid, from the ``started``/``restarted`` events), ``lines`` (the log)."""

    def __init__(self, *args: str, env: dict[str, str] | None = None, echo: bool = False) -> None:
        exe = Path(sys.executable).parent / "contgrasp-launch"
        env = dict(os.environ if env is None else env, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
        read_fd, write_fd = os.pipe()
        try:
            self.proc = subprocess.Popen([str(exe), "--json", "--events", f"fd:{write_fd}", *args], stdout=subprocess.PIPE,
                                         stderr=subprocess.PIPE, text=True, env=env, pass_fds=(write_fd,))
        except BaseException:
            os.close(read_fd)
            raise
        finally:
            os.close(write_fd)  # the launcher holds the only write end: EOF when it exits
        self.lines: list[str] = []
        self.events: list[dict[str, Any]] = []
        self.pids: dict[str, int] = {}
        self._echo = echo
        self._stdout: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self._event_reader = threading.Thread(target=self._read_events, args=(os.fdopen(read_fd),), daemon=True)
        self._event_reader.start()
        # stdout (the JSON summary) is drained by its own thread: communicate() would also read
        # stderr and steal lines from the log reader
        stdout = self.proc.stdout
        assert stdout is not None  # (stdout=PIPE)
        self._out_reader = threading.Thread(target=lambda: self._stdout.append(stdout.read()), daemon=True)
        self._out_reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line)
            if self._echo:
                sys.stderr.write(line)

    def _read_events(self, stream: Any) -> None:
        with stream:
            for line in stream:
                if not line.strip():
                    continue
                event = parse_event(line)
                if event["event"] in ("started", "restarted"):
                    self.pids[event["node"]] = int(event["pid"])
                self.events.append(event)

    def wait_event(self, event: str, timeout: float = 120.0, start: int = 0, **fields: Any) -> int:
        """Index of the first event from ``start`` on of kind ``event`` with these field values;
        AssertionError on timeout or when the launcher ended without it."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for i, e in enumerate(self.events[start:], start):
                if e["event"] == event and all(e.get(k) == v for k, v in fields.items()):
                    return i
            if not self._event_reader.is_alive():
                break
            time.sleep(0.05)
        raise AssertionError(f"no {event!r} event with {fields}; events: {self.events[-20:]}\nlast lines:\n{''.join(self.lines[-30:])}")

    def wait_for(self, pattern: str, timeout: float = 120.0, start: int = 0) -> int:
        """Index of the first log line from ``start`` on matching ``pattern``; AssertionError on timeout."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for i, line in enumerate(self.lines[start:], start):
                if re.search(pattern, line):
                    return i
            if self.proc.poll() is not None and not self._reader.is_alive():
                break
            time.sleep(0.05)
        raise AssertionError(f"no line matching {pattern!r}; last lines:\n{''.join(self.lines[-30:])}")

    def signal(self, name: str, sig: int) -> None:
        """Send ``sig`` to the node process ``name`` (its latest pid)."""
        os.kill(self.pids[name], sig)

    def result(self, timeout: float = 300.0) -> tuple[int, dict[str, Any]]:
        """Wait for the launcher; (exit code, JSON summary)."""
        self.proc.wait(timeout=timeout)
        self._out_reader.join(timeout=30)
        self._reader.join(timeout=30)
        self._event_reader.join(timeout=30)
        out = "".join(self._stdout)
        try:
            return self.proc.returncode, json.loads(out)
        except json.JSONDecodeError:
            raise AssertionError(f"the launcher exited {self.proc.returncode} without a JSON summary (stdout {out[:200]!r}); "
                                 f"its last lines:\n{''.join(self.lines[-40:])}") from None

    def close(self) -> None:
        """Stop the launcher if it is still running: SIGINT (it stops its nodes and finalises the
        recording); if it does not end, SIGKILL it and every node pid it announced."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=30)
                for pid in self.pids.values():  # its nodes would be orphaned
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
