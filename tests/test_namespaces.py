"""Namespaces: the graph's names resolve under a node's namespace, and two graphs under two
namespaces share one ROS domain, each equal to the core loop."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

from contgrasp_core.rod.session import run_sampled  # noqa: E402
from contgrasp_core.scenario import Scenario  # noqa: E402
from contgrasp_ros.launcher.graph import default_params_file, load_params  # noqa: E402
from contgrasp_ros.nodes.boundary_sensor import BoundarySensor  # noqa: E402
from contgrasp_ros.plumbing import topics  # noqa: E402

from conftest import fresh_domain_id  # noqa: E402

BIN = Path(sys.executable).parent


def test_names_resolve_under_the_namespace() -> None:
    assert topics.resolve(topics.ROD_STATE) == "/contgrasp/rod_state"  # (no namespace: the names as before)
    assert topics.resolve(topics.ROD_STATE, "/r1") == topics.resolve(topics.ROD_STATE, "r1/") == "/r1/contgrasp/rod_state"
    assert topics.resolve(topics.DIAGNOSTICS, "/r1") == "/diagnostics"  # (global by convention)
    assert topics.namespace_arguments("/") == []
    assert topics.namespace_arguments("lab/r1") == ["-r", "__ns:=/lab/r1", "-r", "/clock:=/lab/r1/clock"]
    assert topics.status_name("rod_simulator") == "rod_simulator"
    assert topics.status_name("rod_simulator", "/r1") == "r1/rod_simulator"
    assert topics.recorded_namespace(["/diagnostics", "/r1/clock", "/r1/contgrasp/rod_state"]) == "/r1"
    assert topics.recorded_namespace(["/contgrasp/rod_state", "/r1/contgrasp/rod_state"]) == "/"
    assert topics.recorded_namespace(["/chatter"]) == "/"


def test_a_node_under_a_namespace_uses_its_names(ros_context) -> None:  # type: ignore[no-untyped-def]
    """A graph node moved by the launcher's remapping rules: its topics, clock, drop counts and
    status carry the namespace."""
    node = BoundarySensor(context=ros_context, cli_args=["--ros-args", *topics.namespace_arguments("r1")])
    try:
        assert node.get_fully_qualified_name() == "/r1/boundary_sensor"
        assert node.pub.topic_name == "/r1/contgrasp/contact"
        assert node.pub_sampled.topic_name == "/r1/contgrasp/contact/sampled"
        assert node.resolve_topic_name(topics.CLOCK) == "/r1/clock"  # (what its time source subscribes to)
        subscribed = dict(node.get_subscriber_names_and_types_by_node("boundary_sensor", "/r1"))
        assert {"/r1/contgrasp/rod_state", "/r1/contgrasp/rod_state/sampled", "/r1/contgrasp/object", "/r1/clock"} <= set(subscribed)
        node.drops.drop(topics.ROD_STATE, "test")
        assert node.drops.counts == {"/r1/contgrasp/rod_state: test": 1}
        assert node.diagnostics.status().name == "r1/boundary_sensor"
    finally:
        node.destroy_node()


@pytest.mark.heavy
def test_two_namespaced_graphs_in_one_domain_each_equal_the_core_loop() -> None:
    """``contgrasp-launch --namespace a`` and ``b`` started together on one domain: each graph
    runs its own loop on its own clock, bit for bit the core loop's, no deadline missed."""
    domain = fresh_domain_id()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain))
    runs = {ns: subprocess.Popen([str(BIN / "contgrasp-launch"), "--namespace", ns, "--domain-id", str(domain), "--no-record",
                                  "--json", "--duration", "0.6"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 env=env)
            for ns in ("a", "b")}
    seen: set[str] = set()
    context = rclpy.context.Context()
    rclpy.init(context=context, domain_id=domain)
    probe = rclpy.create_node("namespace_probe", context=context)
    try:
        end = time.monotonic() + 120
        while any(p.poll() is None for p in runs.values()) and time.monotonic() < end:
            seen.update(name for name, _ in probe.get_topic_names_and_types())
            time.sleep(0.1)
    finally:
        probe.destroy_node()
        rclpy.shutdown(context=context)
    out = {}
    for ns, proc in runs.items():
        stdout, stderr = proc.communicate(timeout=60)
        assert proc.returncode == 0, stderr[-3000:]
        out[ns] = json.loads(stdout)
    for ns in ("a", "b"):
        assert {f"/{ns}/clock", f"/{ns}/contgrasp/rod_state", f"/{ns}/contgrasp/couple", f"/{ns}/contgrasp/quality"} <= seen
    assert not {"/clock", "/contgrasp/rod_state"} & seen  # (nothing left at the root)
    params = load_params(default_params_file())
    params["rod_simulator"]["duration"] = 0.6
    core = run_sampled(Scenario.from_ros_parameters(params)).observe()
    for ns, summary in out.items():
        assert summary["missed_deadlines"] == 0, ns
        assert summary["steps"] == core.k, ns
        np.testing.assert_array_equal(summary["final"]["x"], core.x[:, 0])
        np.testing.assert_array_equal(summary["final"]["y"], core.x[:, 1])
