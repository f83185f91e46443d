"""The launcher's JSON-lines events (contgrasp_ros.launcher.events, `contgrasp-launch --events`): the
format, the channels, and the launcher's first and last events. The events of real runs
(started/exited/restarted/resumed with real pids) are checked in tests/test_faults.py, whose
LaunchHandle follows the launcher through them."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Any

import pytest

from contgrasp_core.errors import InvalidParameterError, WriteError
from contgrasp_ros.launcher.events import EVENTS, EventWriter, open_events, parse_event, read_events


def test_each_event_is_one_json_object_per_line() -> None:
    buf = io.StringIO()
    w = EventWriter(buf)
    w("domain_id", domain_id=42, mode="processes")
    w("started", node="rod_simulator", pid=1234)
    w("exited", node="rod_simulator", pid=1234, exit_code=-9, action="restarted")
    w("finished", exit_code=0, error=None)
    lines = buf.getvalue().splitlines()
    assert len(lines) == 4 and all(line.startswith("{") and line.endswith("}") for line in lines)
    got = list(read_events(lines))
    assert [e["event"] for e in got] == ["domain_id", "started", "exited", "finished"]
    assert got[1] == {"event": "started", "time": got[1]["time"], "node": "rod_simulator", "pid": 1234}
    assert got[2]["exit_code"] == -9 and got[3]["error"] is None
    assert all(isinstance(e["time"], float) for e in got)
    assert got == [json.loads(line) for line in lines]


def test_unknown_or_malformed_events_are_rejected() -> None:
    with pytest.raises(ValueError, match="unknown launcher event"):
        EventWriter(io.StringIO())("exploded")
    with pytest.raises(ValueError):
        EventWriter(io.StringIO())("finished", exit_code=float("nan"))  # not JSON
    for bad in ("[launcher] started x (pid 1)", "[1, 2]", '{"event": "nope"}', '{"node": "x"}'):
        with pytest.raises(ValueError):
            parse_event(bad)
    assert list(read_events(["", "  \n", '{"event": "resumed", "restart": false}\n'])) == [{"event": "resumed", "restart": False}]
    assert set(EVENTS) == {"domain_id", "started", "restarted", "exited", "resumed", "finished"}


def test_channels_file_fd_and_stdout(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    w = open_events(str(tmp_path / "events.jsonl"))
    w("resumed", restart=True)
    w.close()
    assert [e["event"] for e in read_events((tmp_path / "events.jsonl").read_text().splitlines())] == ["resumed"]
    r, wfd = os.pipe()
    w = open_events(f"fd:{wfd}")
    w("resumed", restart=False)
    w.close()  # closes the write end: the reader sees EOF
    with os.fdopen(r) as f:
        assert [e["restart"] for e in read_events(f)] == [False]
    w = open_events("-")
    w("finished", exit_code=1, error="x")
    assert parse_event(capsys.readouterr().out)["error"] == "x"
    with pytest.raises(InvalidParameterError):
        open_events("fd:nope")
    with pytest.raises(WriteError):
        open_events(str(tmp_path / "no" / "such" / "dir" / "events.jsonl"))


def test_launcher_events_start_with_the_domain_id_and_end_with_finished(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The launcher's own events around a (stubbed) graph run, and the error path."""
    pytest.importorskip("rclpy")
    import contgrasp_ros.launcher.graph_run
    from contgrasp_ros.launcher import cli as launcher

    def fake_run(*_a: object, events: Any = None, **_k: object) -> tuple[dict[str, Any], int]:
        events("started", node="rod_simulator", pid=99)
        return {"error": "node 'rod_simulator' exited with code -9"}, 1

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", fake_run)
    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(var, os.environ.get(var, "0"))
    path = tmp_path / "ev.jsonl"
    assert launcher.main(["--no-record", "--domain-id", "17", "--events", str(path)]) == 1
    got = list(read_events(path.read_text().splitlines()))
    assert [e["event"] for e in got] == ["domain_id", "started", "finished"]
    assert got[0]["domain_id"] == 17 and got[0]["mode"] == "processes"
    assert got[-1]["exit_code"] == 1 and got[-1]["error"] == "node 'rod_simulator' exited with code -9"

    def broken(*_a: object, **_k: object) -> None:
        raise InvalidParameterError("n_elements must be >= 2")

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", broken)
    assert launcher.main(["--no-record", "--domain-id", "17", "--events", str(path)]) == 2
    got = list(read_events(path.read_text().splitlines()))
    assert got[-1]["event"] == "finished" and got[-1]["exit_code"] == 2 and "n_elements" in got[-1]["error"]
    # stdout is the summary's with --json
    assert launcher.main(["--no-record", "--json", "--events", "-"]) == 2
