"""A movable object through the ROS graph: its dynamics and a scripted
disturbance as simulator parameters, its motion in the rod states and on the pose/twist
topics, the live wrench input (topic and service), the recording and ``contgrasp analyze``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod.body import motion_summary
from contgrasp_core.rod.disturbance import Disturbance, WrenchInput
from contgrasp_core.scenario import PAPER, Scenario, motion_from_parameters

pytest.importorskip("contgrasp_msgs.msg")

from contgrasp_core.rod.session import run_sampled  # noqa: E402
from contgrasp_ros.plumbing import topics  # noqa: E402
from contgrasp_ros.recordings.analysis import analyze, history  # noqa: E402
from contgrasp_ros.recordings.run_data import load_run  # noqa: E402
from contgrasp_ros.launcher.discovery import use_discovery_profile  # noqa: E402
from contgrasp_ros.launcher.cli import default_params_file, load_params  # noqa: E402

from conftest import fresh_domain_id  # noqa: E402

BIN = Path(sys.executable).parent


def object_params(tmp_path: Path, duration: float, **sim: Any) -> Path:
    """The packaged scenario, coarse and short (as tests/test_ros_graph.py), with the object's
    motion set by ``sim`` (simulator parameters)."""
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = 20
    data["rod_simulator"]["ros__parameters"].update(duration=duration, marker_period=0.02, **sim)
    data["grasp_quality"]["ros__parameters"]["rate_hz"] = 0.0
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def launch(*args: str, domain: int | None = None) -> subprocess.Popen[str]:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return subprocess.Popen([str(BIN / "contgrasp-launch"), "--domain-id", str(domain or fresh_domain_id()), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


# ------------------------------------------------------------------ the live input (core)
def test_live_inputs_act_from_the_next_control_period() -> None:
    """A wrench received while period k is held acts from period k + 1 on; the scripted
    disturbance alone is exactly its own wrench (the core loop's), and nothing at all is None."""
    assert WrenchInput().freeze(0, 0.0) is None
    step = Disturbance("step", (0.1, -0.2, 1e-3), start=0.004)
    scripted = WrenchInput(step)
    for k, t in enumerate((0.0, 0.002, 0.004)):
        got = scripted.freeze(k, t)
        assert got is not None
        np.testing.assert_array_equal(got, step.wrench_at(t))
    live = WrenchInput(step)
    np.testing.assert_array_equal(live.freeze(0, 0.0), np.zeros(3))
    live.hold(np.array([1.0, 0.0, 0.0]))
    live.apply("pulse", (0.0, 2.0, 0.0), duration=0.004)
    assert live.next_step(0) == 1
    np.testing.assert_array_equal(live.freeze(0, 0.0), np.zeros(3))  # (period 0 was fixed already)
    np.testing.assert_array_equal(live.freeze(1, 0.002), [1.0, 2.0, 0.0])
    np.testing.assert_array_equal(live.freeze(2, 0.004), [1.1, 1.8, 1e-3])
    np.testing.assert_array_equal(live.freeze(3, 0.006), [1.1, -0.2, 1e-3])  # the pulse is over
    live.hold(np.zeros(3))
    np.testing.assert_array_equal(live.freeze(4, 0.008), step.wrench_at(0.008))  # released
    live.reset()
    np.testing.assert_array_equal(live.freeze(0, 0.0), np.zeros(3))
    with pytest.raises(InvalidParameterError, match="finite"):
        live.hold(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(InvalidParameterError, match="kind"):
        live.apply("shove", (1.0, 0.0, 0.0))
    with pytest.raises(InvalidParameterError, match="duration"):
        live.apply("pulse", (1.0, 0.0, 0.0), duration=0.0)


# ------------------------------------------------------------------ (c) parameter validation
BAD_MOTION = [
    ({"object_mode": "spring", "object_mass": -1.0}, "object mass"),
    ({"object_mode": "wobbly"}, "object mode"),
    ({"object_mode": "spring", "object_stiffness": [1.0, 2.0]}, "object_stiffness"),
    ({"object_mode": "spring", "object_damping": [1.0, -2.0, 0.0]}, "object damping"),
    ({"object_mode": "free", "disturbance_kind": "step", "disturbance_wrench": [float("nan"), 0.0, 0.0]}, "disturbance wrench"),
    ({"object_mode": "free", "disturbance_kind": "pulse", "disturbance_wrench": [1.0, 0.0, 0.0]}, "duration"),
    ({"disturbance_kind": "step", "disturbance_wrench": [1.0, 0.0, 0.0]}, "movable object"),
]


@pytest.mark.parametrize(("change", "match"), BAD_MOTION, ids=[m for _, m in BAD_MOTION])
def test_bad_object_motion_parameters_are_refused(change: dict[str, Any], match: str) -> None:
    sim = {**PAPER.node_parameters("rod_simulator"), **change}
    with pytest.raises(InvalidParameterError, match=match):
        motion_from_parameters(sim)
    with pytest.raises(InvalidParameterError, match=match):
        Scenario.from_ros_parameters({"rod_simulator": change})


NODE_BAD = [
    (["-p", "object_mode:=spring", "-p", "object_mass:=-1.0"], "object_mass"),
    (["-p", "object_mode:=wobbly"], "object_mode: must be one of"),
    (["-p", "object_mode:=spring", "-p", "object_stiffness:=[1.0, 2.0]"], "object_stiffness must be three numbers"),
    (["-p", "object_mode:=free", "-p", "disturbance_kind:=step", "-p", "disturbance_wrench:=[.nan, 0.0, 0.0]"],
     "disturbance wrench must be three finite numbers"),
    (["-p", "disturbance_kind:=step", "-p", "disturbance_wrench:=[1.0, 0.0, 0.0]"], "movable object"),
]


@pytest.mark.parametrize(("args", "needle"), NODE_BAD, ids=[n for _, n in NODE_BAD])
def test_simulator_with_bad_object_parameters_exits_2_with_one_line(capsys: pytest.CaptureFixture[str], args: list[str],
                                                                    needle: str) -> None:
    from contgrasp_ros.nodes.rod_simulator import RodSimulator
    from contgrasp_ros.plumbing.runtime import run_node

    capsys.readouterr()
    assert run_node(RodSimulator, args=["rod_simulator", "--ros-args", "-p", "start_paused:=true", *args]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("RodSimulator: error: ")]
    assert len(err) == 1 and needle in err[0], err


def test_wrench_inputs_are_validated_and_refused_for_a_fixed_object(ros_context: Any) -> None:
    """A NaN or out-of-plane wrench is dropped and counted; a fixed object refuses the topic and
    the service; the service applies a valid pulse from the next control period on, and refuses
    once the run is over."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.parameter import Parameter

    from contgrasp_msgs.srv import ApplyWrench
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    def wrench(fx: float, fy: float = 0.0, fz: float = 0.0) -> WrenchStamped:
        msg = WrenchStamped()
        msg.header.frame_id = "world"
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = fx, fy, fz
        return msg

    def sim(**values: Any) -> RodSimulator:
        over = [Parameter(k, value=v) for k, v in {"start_paused": True, "n_elements": 20, **values}.items()]
        return RodSimulator(context=ros_context, parameter_overrides=over)

    fixed = sim()
    try:
        fixed.on_wrench(wrench(1.0))
        assert fixed.drops.counts == {f"{topics.resolve(topics.OBJECT_WRENCH)}: object is fixed": 1}
        resp = fixed.on_apply_wrench(ApplyWrench.Request(kind="step", wrench=[1.0, 0.0, 0.0]), ApplyWrench.Response())
        assert not resp.success and "fixed" in resp.message
    finally:
        fixed.destroy_node()
    spring = sim(object_mode="spring", object_stiffness=[10.0, 10.0, 0.01])
    try:
        spring.on_wrench(wrench(float("nan")))
        spring.on_wrench(wrench(1.0, fz=2.0))
        assert spring.drops.counts == {f"{topics.resolve(topics.OBJECT_WRENCH)}: NaN/Inf": 1, f"{topics.resolve(topics.OBJECT_WRENCH)}: out of plane": 1}
        bad = spring.on_apply_wrench(ApplyWrench.Request(kind="pulse", wrench=[0.0, 1.0, 0.0], duration=-1.0),
                                     ApplyWrench.Response())
        assert not bad.success and "duration" in bad.message
        spring.on_wrench(wrench(0.5, 0.25))
        ok = spring.on_apply_wrench(ApplyWrench.Request(kind="pulse", wrench=[0.0, 1.0, 0.0], duration=0.004),
                                    ApplyWrench.Response())
        assert ok.success and ok.step == 0  # nothing went out yet: from the first state on
        np.testing.assert_array_equal(spring.wrenches.freeze(0, 0.0), [0.5, 1.25, 0.0])
        assert spring.on_apply_wrench(ApplyWrench.Request(kind="step", wrench=[0.0, 0.0, 1e-3]), ApplyWrench.Response()).step == 1
        spring.session.finished = True  # (as at the end of a run)
        over = spring.on_apply_wrench(ApplyWrench.Request(kind="step", wrench=[0.0, 0.0, 1e-3]), ApplyWrench.Response())
        assert not over.success and "the run is over" in over.message
    finally:
        spring.destroy_node()


def test_markers_draw_the_object_where_it_is() -> None:
    """The outline marker follows a movable object's displacement (a circle: its points are R
    from the moved centre); the contact marker is judged against the moved object."""
    from dataclasses import replace

    from std_msgs.msg import Header

    from contgrasp_core.rod.body import BodyState, ObjectDynamics
    from contgrasp_core.rod.session import LoopSession
    from contgrasp_ros.plumbing.markers import scene_markers

    scenario = replace(PAPER, rod=replace(PAPER.rod, n_elements=20), dynamics=ObjectDynamics("free"))
    system = scenario.system()
    assert system.body is not None
    obs = LoopSession(system, scenario.loop).observe()
    boundary = scenario.object.boundary()

    def markers(q: tuple[float, float, float]) -> Any:
        moved = replace(obs, body=BodyState(q=np.array(q), v=np.zeros(3)))
        return scene_markers(boundary, moved, Header(), system.body.centroid).markers  # type: ignore[union-attr]

    outline = np.array([[p.x, p.y] for p in markers((0.01, -0.02, 0.3))[1].points])
    np.testing.assert_allclose(np.hypot(*(outline - (0.09, 0.06)).T), 0.025, rtol=0, atol=1e-12)
    # the straight arm along the x axis touches the circle only once it is moved down onto it
    assert markers((0.0, 0.0, 0.0))[2].points == []
    touching = np.array([[p.x, p.y] for p in markers((0.0, -0.06, 0.0))[2].points])
    assert len(touching) > 0 and np.all(np.abs(touching[:, 0] - 0.08) < 0.025)


# ------------------------------------------------------------------ (a) lock-step determinism
@pytest.mark.heavy
@pytest.mark.parametrize(("mode", "extra"), [
    ("free", {"disturbance_kind": "step", "disturbance_wrench": [0.01, -0.005, 1e-5], "disturbance_start": 0.02}),
    ("spring", {"object_stiffness": [10.0, 10.0, 0.01], "object_damping": [0.05, 0.05, 1e-4], "disturbance_kind": "pulse",
                "disturbance_wrench": [0.0, -0.05, 2e-4], "disturbance_start": 0.01, "disturbance_duration": 0.04}),
])
def test_a_movable_object_with_a_scripted_disturbance_runs_through_the_graph_as_the_core_loop(
        tmp_path: Path, mode: str, extra: dict[str, Any]) -> None:
    """Separate node processes in lock-step equal run_sampled of the same scenario bit for bit:
    the arm, the object's displacement and velocity, and the wrench of every period (in the
    recording), and the recording's pose topic has the object where the rod states have it."""
    params = object_params(tmp_path, 0.1, object_mode=mode, **extra)
    proc = launch("--json", "--params", str(params), "--bag", str(tmp_path / "bag"))
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err[-3000:]
    summary = json.loads(out)
    assert summary["missed_deadlines"] == 0
    scenario = Scenario.from_ros_parameters(load_params(params))
    assert scenario.dynamics.mode == mode and scenario.disturbance is not None
    session = run_sampled(scenario)
    obs = session.observe()
    assert obs.body is not None and np.any(obs.body.q != 0.0)
    assert summary["steps"] == obs.k
    np.testing.assert_array_equal(summary["final"]["x"], obs.x[:, 0])
    np.testing.assert_array_equal(summary["final"]["y"], obs.x[:, 1])
    assert {k: summary[k] for k in ("object_displacement", "object_velocity")} == motion_summary(obs.body.q, obs.body.v)
    run = load_run(tmp_path / "bag")
    assert run.rod.object is not None and int(run.rod.step[-1]) == obs.k
    np.testing.assert_array_equal(run.rod.object.q[-1], obs.body.q)
    np.testing.assert_array_equal(run.rod.object.v[-1], obs.body.v)
    np.testing.assert_array_equal(run.rod.object.wrench, [scenario.disturbance.wrench_at(t) for t in run.rod.t])
    names = {t["name"]: t["count"] for t in run.topics}
    assert names[topics.resolve(topics.OBJECT_POSE)] == names[topics.resolve(topics.OBJECT_TWIST)] == names[topics.resolve(topics.ROD_STATE)] == obs.k + 1
    result = analyze(tmp_path / "bag", csv_dir=tmp_path / "csv")
    assert result["max_recompute_error"] == 0.0  # sensed in the object's frame, as the sensor did
    assert result["object_motion"]["mode"] == mode and result["object_motion"]["final_q"] == obs.body.q.tolist()
    assert result["object_displacement"] == summary["object_displacement"]  # (analyze: the same summary)
    assert result["object_velocity"] == summary["object_velocity"]
    rows = np.loadtxt(result["csv"]["object"]["path"], delimiter=",", skiprows=1)
    assert rows.shape == (obs.k + 1, 11)
    np.testing.assert_array_equal(rows[-1, 2:5], obs.body.q)
    # the run figure (launcher --plot, analyze --plot) draws the object where the last snapshot has it
    from contgrasp_core.figures.run import build_run_figure
    from contgrasp_core.rod.body import to_world

    hist = history(run)
    fig = build_run_figure({"history": hist}, run.params)
    moved = [ln for ln in fig.subfigs[0].axes[0].lines if ln.get_label().startswith("object at")]
    _, pts = scenario.object.boundary().sample(720)
    expected = to_world(pts, np.asarray(hist[-1]["object_q"]), np.asarray(run.rod.object.centroid[0]))
    assert len(moved) == 1 and np.allclose(moved[0].get_xydata()[:-1], expected)


PUSHER = """
import json, sys
import rclpy
from rclpy.executors import ExternalShutdownException
from geometry_msgs.msg import WrenchStamped
from contgrasp_msgs.msg import RodState
from contgrasp_msgs.srv import ApplyWrench
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.plumbing.executor import LeanExecutor

args = json.loads(sys.argv[1])
rclpy.init()
node = rclpy.create_node("pusher")
latest = {"step": -1}
node.create_subscription(RodState, topics.ROD_STATE, lambda m: latest.update(step=int(m.step)), qos.STREAM)
pub = node.create_publisher(WrenchStamped, topics.OBJECT_WRENCH, qos.STREAM)
client = node.create_client(ApplyWrench, topics.APPLY_WRENCH)
msg = WrenchStamped()
msg.header.frame_id = "world"
msg.wrench.force.x, msg.wrench.force.y = args["push"][0], args["push"][1]
ex = LeanExecutor()
ex.add_node(node)
future = None
try:
    while rclpy.ok():
        ex.spin_once(timeout_sec=0.02)
        if latest["step"] >= 20:
            pub.publish(msg)  # (from step 20 on, with every turn: held until the end)
        if latest["step"] >= 60 and future is None:
            future = client.call_async(ApplyWrench.Request(kind="pulse", wrench=[0.0, 0.0, args["torque"]], duration=0.04))
except (KeyboardInterrupt, ExternalShutdownException):
    pass
done = future is not None and future.done()
print(json.dumps({"success": done and future.result().success, "step": future.result().step if done else None}))
"""


# ------------------------------------------------------------------ (b) a push by hand
@pytest.mark.heavy
def test_a_push_on_the_wrench_topic_and_a_pulse_from_the_service_are_in_the_recording(tmp_path: Path) -> None:
    """While a spring-held object is grasped, a node of the test pushes it on the wrench topic
    from step 20 on and applies a torque pulse through ~/apply_wrench: the recording holds the
    push, the wrench of every period (from the period after each input), and the object's
    motion in the direction of the push; ``contgrasp analyze`` reports both."""
    push, torque = (0.0, -0.05, 0.0), 2e-4
    # 500 steps; the coarse arm reaches the object after ~0.45-0.75 s (when depends on the push)
    # and its 1 mm tip sinks ~4 mm into it on impact: a penetration limit
    params = object_params(tmp_path, 1.0, object_mode="spring", object_stiffness=[10.0, 10.0, 0.01],
                           object_damping=[0.05, 0.05, 1e-4], max_penetration_limit=0.01)
    domain = fresh_domain_id()
    # the pusher is a process of its own started with the graph and, like the launcher's nodes,
    # with contgrasp's discovery profile: a participant that was up before the graph is found
    # only at its next periodic announcement (~3 s; the run would be half over)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    use_discovery_profile(env)
    pusher = subprocess.Popen([sys.executable, "-c", PUSHER, json.dumps({"push": push, "torque": torque})],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    proc = launch("--json", "--params", str(params), "--bag", str(tmp_path / "bag"), domain=domain)
    try:
        out, err = proc.communicate(timeout=300)
        pusher.send_signal(signal.SIGINT)
        pushed_out, pushed_err = pusher.communicate(timeout=60)
    finally:
        for p in (proc, pusher):
            if p.poll() is None:
                p.kill()
    assert proc.returncode == 0, err[-3000:]
    assert json.loads(out)["missed_deadlines"] == 0
    assert pusher.returncode == 0, pushed_err[-3000:]
    pulse = json.loads(pushed_out)
    assert pulse["success"], pulse
    pulse_step = int(pulse["step"])

    run = load_run(tmp_path / "bag")
    o = run.rod.object
    assert o is not None and np.all(np.diff(run.rod.step) == 1)
    assert {t["name"]: t["count"] for t in run.topics}.get(topics.resolve(topics.OBJECT_WRENCH), 0) > 0  # the push itself
    pushed = np.flatnonzero(o.wrench[:, 1] != 0.0)
    first = int(run.rod.step[pushed[0]])
    assert first > 20  # the period after the first push received (published once step 20 was seen)
    assert np.all(o.wrench[pushed[0]:, :2] == push[:2])  # held until the end
    assert np.all(o.q[: pushed[0] + 1] == 0.0)  # at rest until pushed (the arm reaches it later)
    assert int(run.rod.step[pushed[0]]) < 400, "the test node reacted too late (a busy machine?)"
    assert o.q[pushed[0]:, 1].min() < -1e-3  # moved the way it was pushed (5 mm on the spring at rest)
    rows = np.flatnonzero(o.wrench[:, 2] != 0.0)
    assert 60 < int(run.rod.step[rows[0]]) == pulse_step < 475 and len(rows) in (20, 21)  # 0.04 s: 20 control periods
    assert np.all(o.wrench[rows, 2] == torque) and np.any(o.q[:, 2] > 0)
    result = analyze(tmp_path / "bag")
    w = result["object_motion"]["wrench"]
    assert w["max_force"] == pytest.approx(0.05) and w["max_torque"] == torque
    assert w["first_t"] == pytest.approx(float(run.rod.t[pushed[0]]))
    assert result["object_motion"]["max_displacement"] >= -o.q[:, 1].min() and result["max_recompute_error"] == 0.0


@pytest.mark.parametrize(("args", "needle"), [(["-p", "object:=banana"], "unknown object 'banana'"),
                                              (["-p", "object_center:=[0.1]"], "object centre must be two numbers")])
def test_controller_with_a_bad_object_copy_exits_2_with_one_line(capsys: pytest.CaptureFixture[str], args: list[str],
                                                                 needle: str) -> None:
    """The controller's copy of the object (law hold plans on it) is checked at start under every
    law, as the simulator's: nonsense stops the node in one line, exit 2."""
    from contgrasp_ros.nodes.grasp_controller import GraspController
    from contgrasp_ros.plumbing.runtime import run_node

    capsys.readouterr()
    assert run_node(GraspController, args=["grasp_controller", "--ros-args", *args]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("GraspController: error: ")]
    assert len(err) == 1 and needle in err[0], err
