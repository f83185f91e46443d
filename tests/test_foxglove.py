"""A run watched live without a ROS install: `contgrasp-launch --foxglove PORT` serves the graph
over the Foxglove WebSocket protocol; a plain WebSocket client (as the Foxglove app is)
subscribes and receives the rod states while the graph runs."""

from __future__ import annotations

import json
import signal
import socket
import struct
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

pytest.importorskip("contgrasp_msgs.msg")
pytest.importorskip("foxglove")
websockets_client = pytest.importorskip("websockets.sync.client")

from conftest import fresh_domain_id  # noqa: E402
from contgrasp_ros.launcher.launch_handle import LaunchHandle  # noqa: E402
from contgrasp_ros.launcher.cli import default_params_file  # noqa: E402

SUBPROTOCOL = "foxglove.sdk.v1"  # the Foxglove WebSocket protocol as foxglove-sdk serves it
MESSAGE_DATA = 0x01  # binary opcode of a message


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def connect(port: int, timeout: float = 120.0) -> Any:
    end = time.monotonic() + timeout
    while True:
        try:
            return websockets_client.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=5)
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.2)


@pytest.mark.heavy
def test_launcher_serves_the_run_live_to_a_foxglove_client(tmp_path: Path) -> None:
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = 20
    data["rod_simulator"]["ros__parameters"]["duration"] = 100.0  # runs until we have seen enough
    # the coarse rod's 1 mm tip sinks ~1-4 mm into the object on impact (t ~ 0.66 s): with the
    # default limit (the tip radius) the run stops there, before a late client has seen enough
    data["rod_simulator"]["ros__parameters"]["max_penetration_limit"] = 0.01
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    port = free_port()
    launch = LaunchHandle("--params", str(params), "--no-record", "--foxglove", str(port),
                          "--domain-id", str(fresh_domain_id()))
    try:
        with connect(port) as ws:
            assert ws.subprotocol == SUBPROTOCOL
            channels: dict[str, dict[str, Any]] = {}
            end = time.monotonic() + 60
            while not {"/contgrasp/rod_state", "/contgrasp/scene"} <= set(channels) and time.monotonic() < end:
                msg = ws.recv(timeout=60)
                if isinstance(msg, str) and json.loads(msg).get("op") == "advertise":
                    channels.update({c["topic"]: c for c in json.loads(msg)["channels"]})
            rod, scene = channels["/contgrasp/rod_state"], channels["/contgrasp/scene"]
            assert rod["encoding"] == "json" and scene["schemaName"] == "foxglove.SceneUpdate"
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": rod["id"]},
                                                                      {"id": 2, "channelId": scene["id"]}]}))
            states: list[tuple[int, dict[str, Any]]] = []
            scenes = 0
            while (len(states) < 20 or not scenes) and time.monotonic() < end + 60:
                msg = ws.recv(timeout=60)
                if isinstance(msg, bytes) and msg[0] == MESSAGE_DATA:
                    sub, log_time = struct.unpack_from("<IQ", msg, 1)
                    if sub == 1:
                        states.append((log_time, json.loads(msg[13:])))
                    elif sub == 2:
                        scenes += 1
        steps = [s["step"] for _, s in states]
        assert steps == sorted(steps) and len(set(steps)) == len(steps) >= 20  # the loop, live
        for log_time, s in states:
            assert log_time == round(s["t"] * 1e9)  # logged at simulated time
            assert len(s["x"]) == len(s["y"]) == 21
        assert scenes >= 1
        launch.proc.send_signal(signal.SIGINT)
        code, out = launch.result(timeout=120)
    finally:
        launch.close()
    assert code == 130 and out["foxglove"] == f"ws://127.0.0.1:{port}"


def test_launcher_refuses_a_bad_port() -> None:
    import subprocess
    import sys

    for bad in ("70000", "-1", "x"):
        out = subprocess.run([str(Path(sys.executable).parent / "contgrasp-launch"), f"--foxglove={bad}", "--no-record"],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1 and "--foxglove" in out.stderr


def test_bridge_drops_and_counts_malformed_messages(ros_context) -> None:  # type: ignore[no-untyped-def]
    """A malformed rod or contact state is dropped with its reason and counted; the bridge keeps
    serving well-formed ones."""
    from rclpy.parameter import Parameter
    from std_msgs.msg import Header

    from contgrasp_msgs.msg import ContactState, RodState
    from contgrasp_ros.nodes.foxglove_bridge import FoxgloveBridge

    node = FoxgloveBridge(context=ros_context, parameter_overrides=[Parameter("port", value=0)])
    try:
        n = 5
        good = RodState(header=Header(), step=0, s=[0.0, 0.05, 0.1, 0.15, 0.2], x=[0.0] * n, y=[0.0, 0.05, 0.1, 0.15, 0.2],
                        theta=[1.5] * n, kappa=[0.0] * n, radius=[0.01] * n)
        bad = RodState(header=Header(), step=1, s=good.s, x=[0.0] * 3, y=good.y, theta=good.theta, kappa=good.kappa,
                       radius=good.radius)
        node.on_rod_state(bad)
        node.on_contact(ContactState(header=Header(), step=1, s=[0.0, 1.0], rho=[float("nan"), 1.0]))
        assert node.drops.total == 2 and not any("internal error" in k for k in node.drops.counts)
        node.on_rod_state(good)  # still serving
        assert node.drops.total == 2
    finally:
        node.destroy_node()
