"""Run ``contgrasp-launch`` in the background and follow it: child pids, log lines, result.

Used by the fault-injection tests and the soak benchmark (and handy for scripting runs): the
launcher announces each node process it starts (``[launcher] started NAME (pid N)``) on stderr;
:class:`LaunchHandle` reads that stream in a thread, so callers can wait for a log line, signal
one node by its pid, and collect the JSON summary at the end.
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

__all__ = ["LaunchHandle"]

_STARTED = re.compile(r"\[launcher\] started (\w+) \(pid (\d+)\)")


class LaunchHandle:
    """``contgrasp-launch --json ARGS`` as a child process with its stderr followed."""

    def __init__(self, *args: str, env: dict[str, str] | None = None, echo: bool = False) -> None:
        exe = Path(sys.executable).parent / "contgrasp-launch"
        env = dict(os.environ if env is None else env, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen([str(exe), "--json", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        self.lines: list[str] = []
        self.pids: dict[str, int] = {}
        self._echo = echo
        self._stdout: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
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
            if m := _STARTED.match(line):
                self.pids[m.group(1)] = int(m.group(2))

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
        return self.proc.returncode, json.loads("".join(self._stdout))

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
