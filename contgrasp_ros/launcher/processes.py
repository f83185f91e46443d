"""Child-process management for the launcher: start, prefix output, stop in escalating steps,
and clear the shared-memory files that stopped (above all killed) DDS participants leave."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from contgrasp_ros.launcher.events import EventSink

__all__ = ["Child", "ProcessGroup", "clean_shared_memory", "remove_orphans"]

_COLOURS = ("\033[36m", "\033[35m", "\033[33m", "\033[32m", "\033[34m", "\033[31m")
_RESET = "\033[0m"


@dataclass
class Child:
    """One node process with its name and the thread that prefixes its output."""

    name: str
    cmd: list[str]
    proc: subprocess.Popen[bytes]
    pump: threading.Thread = field(repr=False)


class ProcessGroup:
    """Starts node processes with a shared environment and stops them cleanly.

    Each child's stdout and stderr are merged and echoed line by line to ``sink`` (stderr by
    default, so the launcher's stdout stays free for ``--json``), prefixed with ``[name]`` and
    coloured when the sink is a terminal. Each start is announced on ``sink`` and, given
    ``events``, as a ``started``/``restarted`` event (:mod:`contgrasp_ros.launcher.events`).
    """

    def __init__(self, env: dict[str, str], sink: IO[str] | None = None, events: EventSink | None = None) -> None:
        self.env = env
        self.events = events
        self.sink = sink if sink is not None else sys.stderr
        self.children: list[Child] = []
        self.pids: set[int] = set()  # every process this group started, restarts included
        self._colour = hasattr(self.sink, "isatty") and self.sink.isatty()
        self._lock = threading.Lock()

    def start(self, name: str, cmd: list[str]) -> Child:
        proc = subprocess.Popen(cmd, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
        colour = _COLOURS[len(self.children) % len(_COLOURS)] if self._colour else ""
        prefix = f"{colour}[{name}]{_RESET if colour else ''} "
        pump = threading.Thread(target=self._pump, args=(proc, prefix), daemon=True)
        pump.start()
        child = Child(name, cmd, proc, pump)
        self.children.append(child)
        self._announce(child, "started")
        return child

    def _announce(self, child: Child, event: str) -> None:
        self.pids.add(child.proc.pid)
        with self._lock:
            print(f"[launcher] started {child.name} (pid {child.proc.pid})", file=self.sink, flush=True)
        if self.events is not None:
            self.events(event, node=child.name, pid=child.proc.pid)

    def _pump(self, proc: subprocess.Popen[bytes], prefix: str) -> None:
        assert proc.stdout is not None
        for raw in iter(proc.stdout.readline, b""):
            line = raw.decode(errors="replace").rstrip("\n")
            with self._lock:
                print(prefix + line, file=self.sink, flush=True)

    def restart(self, child: Child) -> Child:
        """Start an exited child again with the same command (it keeps its place and colour)."""
        i = self.children.index(child)
        child.pump.join(timeout=2.0)
        proc = subprocess.Popen(child.cmd, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
        colour = _COLOURS[i % len(_COLOURS)] if self._colour else ""
        pump = threading.Thread(target=self._pump, args=(proc, f"{colour}[{child.name}]{_RESET if colour else ''} "), daemon=True)
        pump.start()
        self.children[i] = Child(child.name, child.cmd, proc, pump)
        self._announce(self.children[i], "restarted")
        return self.children[i]

    def exited(self) -> list[Child]:
        """Children that have exited."""
        return [c for c in self.children if c.proc.poll() is not None]

    def stop(self, *, names: Sequence[str] | None = None, sigint_timeout: float = 10.0, sigterm_timeout: float = 5.0) -> dict[str, int]:
        """SIGINT the running children (or only those in ``names``) one after another, each
        given ``sigint_timeout`` to exit, then SIGTERM the rest together, then SIGKILL. Returns
        each stopped child's exit code (negative: killed by that signal).

        One at a time because Fast DDS 2.14 can deadlock a participant that is being destroyed
        while it processes another participant's departure (seen: a node hung in
        ``destroy_participant`` while its receive thread removed a peer's writer, when all the
        graph's nodes were interrupted at once); a node that leaves alone always exits.
        """
        chosen = [c for c in self.children if names is None or c.name in names]
        for c in chosen:
            if c.proc.poll() is None:
                self._signal_and_wait([c], signal.SIGINT, sigint_timeout)
        for sig, timeout in ((signal.SIGTERM, sigterm_timeout), (signal.SIGKILL, 5.0)):
            running = [c for c in chosen if c.proc.poll() is None]
            if not running:
                break
            self._signal_and_wait(running, sig, timeout)
        for c in chosen:
            c.proc.wait()
            c.pump.join(timeout=2.0)
        clean_shared_memory()
        return {c.name: int(c.proc.returncode) for c in chosen}

    @staticmethod
    def _signal_and_wait(children: Sequence[Child], sig: signal.Signals, timeout: float) -> None:
        for c in children:
            try:
                os.kill(c.proc.pid, sig)
            except ProcessLookupError:
                pass
        end = time.monotonic() + timeout
        while time.monotonic() < end and any(c.proc.poll() is None for c in children):
            time.sleep(0.02)


def _fastdds_cleaner() -> Path | None:
    """Fast DDS's own ``fastdds shm clean`` (``tools/fastdds/shm/clean.py`` under a prefix of the
    ROS installation: ``AMENT_PREFIX_PATH``, then this Python's prefix, i.e. the venv)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    for prefix in prefixes:
        tool = Path(prefix) / "tools" / "fastdds" / "shm" / "clean.py"
        if tool.is_file():
            return tool
    return None


def clean_shared_memory() -> int:
    """Remove the Fast DDS shared-memory files (``/dev/shm/fastrtps_*``) no live process holds:
    a participant that was killed, or that never ran its clean-up, leaves them behind. Files in
    use (their lock is held) are kept, so this is safe while other graphs run. Returns the
    number of zombie ports and segments removed (0 where the tool is not installed)."""
    tool = _fastdds_cleaner()
    if tool is None or os.name != "posix":
        return 0
    spec = importlib.util.spec_from_file_location("contgrasp_fastdds_shm_clean", tool)
    if spec is None or spec.loader is None:
        return 0
    module = importlib.util.module_from_spec(spec)
    out = io.StringIO()
    try:
        spec.loader.exec_module(module)
        with contextlib.redirect_stdout(out):  # (it prints a report; the launcher's stdout is JSON)
            module.Clean().run()
    except Exception:  # noqa: BLE001 - a failed clean-up must never fail a run
        return 0
    removed = sum(int(n) for n in re.findall(r"(\d+) zombie (?:ports|segments) cleaned", out.getvalue()))
    return removed + len(remove_orphans())


SHM = Path("/dev/shm")
_ORPHAN = re.compile(r"fastrtps_(port\d+|[0-9a-f]{16})")


def remove_orphans(shm: Path = SHM, min_age_s: float = 2.0) -> list[Path]:
    """Remove the Fast DDS shared-memory files Fast DDS's cleaner cannot judge: port and segment
    files whose lock file is gone (participants that exited normally leave the port segment and
    its mutex behind). Such a file is removed only when no live process maps it (the
    ``/proc/<pid>/maps`` this user can read: a process whose maps it cannot read belongs to
    another user, whose files in the sticky ``/dev/shm`` it cannot remove either, or is the
    machine's init) and it was created more than ``min_age_s`` seconds ago (not one a starting
    participant is setting up). Returns the files removed."""
    mapped: set[str] = set()
    for maps in Path("/proc").glob("[0-9]*/maps"):
        try:
            text = maps.read_text()
        except OSError:
            continue  # ended meanwhile, or not ours (see above)
        mapped.update(line.rsplit(" ", 1)[-1] for line in text.splitlines() if "fastrtps_" in line)
    now = time.time()
    removed = []
    for seg in shm.glob("fastrtps_*"):
        if not _ORPHAN.fullmatch(seg.name) or str(seg) in mapped:
            continue
        if any((shm / f"{seg.name}{lock}").exists() for lock in ("_el", "_sl")):
            continue  # Fast DDS's cleaner judges it by its lock
        try:
            if now - seg.stat().st_ctime < min_age_s:
                continue
            seg.unlink()
        except (FileNotFoundError, PermissionError):
            continue
        removed.append(seg)
        with contextlib.suppress(FileNotFoundError, PermissionError):
            (shm / f"sem.{seg.name}_mutex").unlink()  # (ports only)
    return removed
