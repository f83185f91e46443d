"""Node tests with real middleware: each node in a test executor, fed real messages, its
outputs checked against the core functions; malformed messages are dropped and counted."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from contgrasp_core.arm import Arm, BasePose, shape_from_curvature  # noqa: E402
from contgrasp_core.boundary import circle, ellipse  # noqa: E402
from contgrasp_core.contact import sense  # noqa: E402
from contgrasp_core.quality import quality_of_state  # noqa: E402
from contgrasp_core.scenario import PAPER, QUALITY  # noqa: E402
from contgrasp_msgs.msg import ContactState, GraspQuality, ObjectBoundary, RodState  # noqa: E402
from contgrasp_ros.plumbing import qos, topics  # noqa: E402
from contgrasp_ros.plumbing.convert import boundary_to_msg, contact_to_msg  # noqa: E402
from contgrasp_ros.nodes.boundary_sensor import BoundarySensor  # noqa: E402
from contgrasp_ros.nodes.grasp_quality import GraspQualityNode  # noqa: E402

from conftest import spin_until  # noqa: E402


def rod_msg(step: int, shape, radius, t: float) -> RodState:  # type: ignore[no-untyped-def]
    h = Header(frame_id="world")
    h.stamp.sec, h.stamp.nanosec = int(t), int(round((t - int(t)) * 1e9))
    return RodState(
        header=h,
        step=step,
        s=shape.s.tolist(),
        x=shape.r[:, 0].tolist(),
        y=shape.r[:, 1].tolist(),
        theta=shape.theta.tolist(),
        kappa=[],
        radius=np.broadcast_to(radius, shape.s.shape).tolist(),
    )


@pytest.fixture
def graph(ros_context):  # type: ignore[no-untyped-def]
    nodes = []
    ex = SingleThreadedExecutor(context=ros_context)

    def add(node):  # type: ignore[no-untyped-def]
        nodes.append(node)
        ex.add_node(node)
        return node

    yield ros_context, ex, add
    ex.shutdown()
    for n in nodes:
        n.destroy_node()


def arm_near(boundary, base: BasePose, length: float = 0.2, n: int = 41):  # type: ignore[no-untyped-def]
    s = Arm(length, 0.01, 0.001).grid(n)
    return shape_from_curvature(s, 8.0 + 20.0 * s, base)


def test_boundary_sensor_matches_core_and_survives_bad_messages(graph) -> None:  # type: ignore[no-untyped-def]
    ctx, ex, add = graph
    sensor = add(BoundarySensor(context=ctx))
    probe = add(rclpy.create_node("probe", context=ctx))
    obj_pub = probe.create_publisher(ObjectBoundary, topics.OBJECT, qos.LATCHED)
    rod_pub = probe.create_publisher(RodState, topics.ROD_STATE, qos.STREAM)
    got: list[ContactState] = []
    probe.create_subscription(ContactState, topics.CONTACT, got.append, qos.STREAM)
    obj = circle(0.025, (0.08, 0.08))
    obj_pub.publish(boundary_to_msg(obj, Header(frame_id="world")))
    assert spin_until(ex, lambda: sensor.object.boundary is not None and rod_pub.get_subscription_count() > 0)
    shape = arm_near(obj, BasePose(0.0, 0.0, 0.0))
    radius = np.linspace(0.01, 0.001, len(shape.s))
    rod_pub.publish(rod_msg(3, shape, radius, 1.25))
    assert spin_until(ex, lambda: len(got) == 1)
    ref = sense(shape, obj, radius)
    out = got[0]
    assert out.step == 3 and out.header.stamp.sec == 1 and out.header.stamp.nanosec == 250_000_000
    np.testing.assert_array_equal(out.rho, ref.rho)
    np.testing.assert_array_equal(out.alpha, ref.alpha)
    np.testing.assert_array_equal(out.s_o, ref.s_o)
    np.testing.assert_array_equal(out.in_contact, ref.in_contact)

    bad = rod_msg(4, shape, radius, 1.5)
    bad.x[5] = float("nan")
    short = rod_msg(5, shape, radius, 1.5)
    short.theta = short.theta[:-1]
    empty = RodState()
    for m in (bad, short, empty):
        rod_pub.publish(m)
    assert spin_until(ex, lambda: sensor.drops.total == 3)
    assert sensor.drops.counts == {f"{topics.resolve(topics.ROD_STATE)}: {r}": 1 for r in ("NaN/Inf", "length mismatch", "too few samples")}
    rod_pub.publish(rod_msg(6, shape, radius, 1.75))  # still working
    assert spin_until(ex, lambda: len(got) == 2)
    assert got[1].step == 6
    # a runtime parameter change takes effect; an out-of-range one is refused
    from rclpy.parameter import Parameter

    assert not sensor.set_parameters([Parameter("contact_tolerance", value=-1.0)])[0].successful
    assert sensor.set_parameters([Parameter("contact_tolerance", value=0.5)])[0].successful
    rod_pub.publish(rod_msg(7, shape, radius, 2.0))
    assert spin_until(ex, lambda: len(got) == 3)
    assert all(got[2].in_contact) and got[2].contact_tolerance == 0.5


def test_grasp_quality_node_matches_core(graph) -> None:  # type: ignore[no-untyped-def]
    ctx, ex, add = graph
    node = add(GraspQualityNode(context=ctx))
    from rclpy.parameter import Parameter

    node.set_parameters([Parameter("rate_hz", value=2.0)])
    probe = add(rclpy.create_node("probe", context=ctx))
    obj_pub = probe.create_publisher(ObjectBoundary, topics.OBJECT, qos.LATCHED)
    c_pub = probe.create_publisher(ContactState, topics.CONTACT_SAMPLED, qos.STREAM)  # (the observers' stream)
    got: list[GraspQuality] = []
    probe.create_subscription(GraspQuality, topics.QUALITY, got.append, qos.STREAM)
    obj = ellipse(0.04, 0.02, (0.08, 0.06))
    obj_pub.publish(boundary_to_msg(obj, Header()))
    assert spin_until(ex, lambda: node.object.boundary is not None and c_pub.get_subscription_count() > 0)
    shape = arm_near(obj, BasePose(0.0, 0.0, 0.3))
    state = sense(shape, obj, 0.02, tol=0.01)
    for k, t in enumerate([0.0, 0.1, 0.6]):  # 2 Hz in sim time: the 0.1 s message is skipped
        h = Header()
        h.stamp.sec, h.stamp.nanosec = 0, int(t * 1e9)
        c_pub.publish(contact_to_msg(state, h, k))
    assert spin_until(ex, lambda: len(got) == 2)
    spin_until(ex, lambda: len(got) > 2, timeout=0.3)
    assert [m.step for m in got] == [0, 2]
    paper = PAPER.node_parameters(QUALITY)  # the node's default reference point; the contact set is the state's own
    assert "contact_tolerance" not in paper
    ref = quality_of_state(state, obj, tol=state.tol, ref=(paper["reference_x"], paper["reference_y"]))
    assert got[0].contact_tolerance == state.tol
    np.testing.assert_allclose(np.reshape(got[0].w, (3, 3)), ref.W, rtol=1e-12, atol=1e-15)
    assert got[0].q1 == pytest.approx(ref.Q1, rel=1e-10) and got[0].valid
    bad = contact_to_msg(state, Header(), 9)
    bad.in_contact = bad.in_contact[:3]
    c_pub.publish(bad)
    assert spin_until(ex, lambda: node.drops.total == 1)
    assert node.drops.counts == {f"{topics.resolve(topics.CONTACT_SAMPLED)}: length mismatch": 1}


def _paper_model(n: int = 12):  # type: ignore[no-untyped-def]
    """The paper's rod (the nodes' defaults), coarser."""
    from dataclasses import replace

    return replace(PAPER.rod, n_elements=n)


def test_grasp_controller_matches_core_and_takes_new_gains(graph) -> None:  # type: ignore[no-untyped-def]
    from rclpy.parameter import Parameter

    from contgrasp_core.control import paper_gains
    from contgrasp_core.control import feedback_at_joints
    from contgrasp_msgs.msg import CoupleControl
    from contgrasp_ros.nodes.grasp_controller import GraspController

    ctx, ex, add = graph
    model = _paper_model()
    node = add(GraspController(context=ctx, parameter_overrides=[Parameter("n_elements", value=model.n_elements)]))
    probe = add(rclpy.create_node("probe", context=ctx))
    c_pub = probe.create_publisher(ContactState, topics.CONTACT, qos.STREAM)
    got: list[CoupleControl] = []
    probe.create_subscription(CoupleControl, topics.COUPLE, got.append, qos.STREAM)
    assert spin_until(ex, lambda: c_pub.get_subscription_count() > 0 and probe.count_publishers(topics.COUPLE) > 0)
    obj = circle(0.025, (0.08, 0.08))
    shape = shape_from_curvature(model.s_nodes, np.full(model.n_elements + 1, 5.0), BasePose())
    state = sense(shape, obj, model.radius(model.s_nodes))
    c_pub.publish(contact_to_msg(state, Header(), 4))
    assert spin_until(ex, lambda: len(got) == 1)
    ref = feedback_at_joints(model, paper_gains(model, 0.025), state.rho, state.alpha)
    assert got[0].step == 4
    np.testing.assert_array_equal(got[0].u, ref.u)
    np.testing.assert_array_equal(got[0].du_drho, ref.g_rho)
    np.testing.assert_array_equal(got[0].du_dalpha, ref.g_alpha)
    np.testing.assert_array_equal(got[0].rho_ref, state.rho[:-1])
    np.testing.assert_array_equal(got[0].s, model.joint_s)
    assert not node.set_parameters([Parameter("mu1", value=-1.0)])[0].successful  # out of range: refused
    assert node.set_parameters([Parameter("mu1", value=2.0)])[0].successful
    c_pub.publish(contact_to_msg(state, Header(), 5))
    assert spin_until(ex, lambda: len(got) == 2)
    np.testing.assert_array_equal(got[1].u, feedback_at_joints(model, paper_gains(model, 0.025, mu1=2.0), state.rho, state.alpha).u)
    wrong = sense(shape_from_curvature(np.linspace(0, 0.2, 5), np.zeros(5), BasePose()), obj, 0.01)
    c_pub.publish(contact_to_msg(wrong, Header(), 6))  # 5 nodes for a 12-element rod
    assert spin_until(ex, lambda: node.drops.total == 1)
    assert node.drops.counts == {f"{topics.resolve(topics.CONTACT)}: wrong node count": 1}


def test_rod_simulator_lockstep_timeout_pause_and_reset(graph) -> None:  # type: ignore[no-untyped-def]
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.parameter import Parameter
    from std_srvs.srv import SetBool, Trigger

    from contgrasp_core.rod import Obstacle, RodSystem
    from dataclasses import replace

    from contgrasp_core.rod.session import LoopSession
    from contgrasp_msgs.msg import CoupleControl
    from contgrasp_ros.plumbing.convert import couple_to_msg
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    ctx, ex, add = graph
    model = _paper_model()
    over = [Parameter(k, value=v) for k, v in dict(
        n_elements=model.n_elements, control_period=0.01, start_paused=True, couple_timeout=0.3,
        timeout_fallback="zero", duration=1.0, wait_for_peers=False).items()]  # (the probe plays the controller)
    sim = add(RodSimulator(context=ctx, parameter_overrides=over))
    probe = add(rclpy.create_node("probe", context=ctx))
    states: list[RodState] = []
    status: list[dict[str, str]] = []
    probe.create_subscription(RodState, topics.ROD_STATE, states.append, qos.STREAM)
    probe.create_subscription(
        DiagnosticArray, topics.DIAGNOSTICS, lambda m: status.append({kv.key: kv.value for kv in m.status[0].values}), qos.STREAM
    )
    u_pub = probe.create_publisher(CoupleControl, topics.COUPLE, qos.STREAM)
    pause = probe.create_client(SetBool, "/rod_simulator/pause")
    reset = probe.create_client(Trigger, "/rod_simulator/reset")
    assert spin_until(ex, lambda: pause.service_is_ready() and u_pub.get_subscription_count() > 0)
    spin_until(ex, lambda: False, timeout=0.5)
    assert states == []  # paused: nothing published yet
    fut = pause.call_async(SetBool.Request(data=False))
    assert spin_until(ex, lambda: fut.done() and len(states) == 1)
    ref = LoopSession(RodSystem(model, Obstacle(PAPER.object.boundary())), replace(PAPER.loop, duration=1.0, control_period=0.01))
    np.testing.assert_array_equal(states[0].x, ref.observe().x[:, 0])
    u = np.linspace(-1e-4, 1e-4, model.n_elements)
    u_pub.publish(couple_to_msg(model.joint_s, u, states[0].header, 0))
    assert spin_until(ex, lambda: len(states) == 2)
    ref.advance(u)
    np.testing.assert_array_equal(states[1].y, ref.observe().x[:, 1])
    assert states[1].step == 1 and states[1].header.stamp.nanosec == 10_000_000
    # malformed couple: dropped and counted; then no couple at all: the zero fallback after the timeout
    u_pub.publish(couple_to_msg(model.joint_s[:3], u[:3], states[1].header, 1))
    assert spin_until(ex, lambda: len(states) == 3, timeout=10)
    assert sim.missed == 1 and sim.drops.counts == {f"{topics.resolve(topics.COUPLE)}: wrong joints": 1}
    ref.advance(np.zeros(model.n_elements))
    np.testing.assert_array_equal(states[2].y, ref.observe().x[:, 1])
    assert spin_until(ex, lambda: status and status[-1]["missed_deadlines"] == str(sim.missed))
    # an invalid fallback is refused at run time
    assert not sim.set_parameters([Parameter("timeout_fallback", value="explode")])[0].successful
    fut = reset.call_async(Trigger.Request())
    n_before = len(states)
    assert spin_until(ex, lambda: fut.done() and len(states) > n_before)
    assert states[n_before].step == 0


def _free_running(graph, couple_timeout: float):  # type: ignore[no-untyped-def]
    from rclpy.parameter import Parameter

    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    ctx, ex, add = graph
    over = dict(n_elements=10, lockstep=False, control_period=0.02, duration=10.0, couple_timeout=couple_timeout,
                min_subscribers=1, wait_for_peers=False)  # (state 0 waits for the probe's subscription only)
    sim = add(RodSimulator(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in over.items()]))
    probe = add(rclpy.create_node("probe", context=ctx))
    states: list[RodState] = []
    probe.create_subscription(RodState, topics.ROD_STATE, states.append, qos.STREAM)
    return ex, sim, probe, states


def test_rod_simulator_free_running_starts_with_the_first_couple_then_runs_on_wall_time(graph) -> None:  # type: ignore[no-untyped-def]
    """Free-running mode (real-time demos): state 0 goes out and the schedule starts with the
    run's first couple (the loop closed); from then on the rod advances every control period of
    wall time with the latest couple, whether or not the controller answers again."""
    from contgrasp_msgs.msg import CoupleControl
    from contgrasp_ros.plumbing.convert import couple_to_msg

    ex, sim, probe, states = _free_running(graph, couple_timeout=5.0)
    u_pub = probe.create_publisher(CoupleControl, topics.COUPLE, qos.STREAM)
    assert spin_until(ex, lambda: len(states) >= 1 and u_pub.get_subscription_count() > 0, timeout=20)
    spin_until(ex, lambda: len(states) > 1, timeout=0.5)
    assert {m.step for m in states} == {0}  # (25 control periods: no step without the loop closed; state 0 may be re-sent)
    u_pub.publish(couple_to_msg(sim.model.joint_s, np.zeros(10), states[0].header, 0))
    assert spin_until(ex, lambda: len(states) >= 5, timeout=20)
    assert [m.step for m in states[-3:]] == sorted(m.step for m in states[-3:])


@pytest.mark.heavy
def test_rod_simulator_free_running_steps_with_the_answer_to_each_state_when_it_comes_within_the_wait(graph) -> None:  # type: ignore[no-untyped-def]
    """Free-running with ``couple_wait``: each step waits for the couple answering its own
    state, so a controller that answers in time gives exactly the lock-step run (each state equal
    to the core session advanced with the same couples, bit for bit) and no late couple; the
    same answers held back make every step go on without them after the wait (each counted)."""
    from dataclasses import replace

    from rclpy.parameter import Parameter

    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.session import LoopSession
    from contgrasp_msgs.msg import CoupleControl
    from contgrasp_ros.plumbing.convert import couple_to_msg
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    ctx, ex, add = graph
    model = _paper_model()
    # (a period long enough for an answer on a loaded machine: 0.15 s of wait)
    over = dict(n_elements=model.n_elements, lockstep=False, control_period=0.2, couple_wait=0.75, duration=10.0,
                min_subscribers=1, wait_for_peers=False)
    sim = add(RodSimulator(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in over.items()]))
    probe = add(rclpy.create_node("probe", context=ctx))
    u_pub = probe.create_publisher(CoupleControl, topics.COUPLE, qos.STREAM)
    states: list[RodState] = []
    answer = [True]

    def on_state(m: RodState) -> None:
        states.append(m)
        if answer[0]:
            u_pub.publish(couple_to_msg(model.joint_s, np.full(model.n_elements, 1e-4 * (m.step + 1)), m.header, m.step))

    probe.create_subscription(RodState, topics.ROD_STATE, on_state, qos.STREAM)
    assert spin_until(ex, lambda: len(states) >= 4, timeout=30)
    assert sim.wait.late == 0
    ref = LoopSession(RodSystem(model, Obstacle(PAPER.object.boundary())), replace(PAPER.loop, duration=10.0, control_period=0.2))
    for k, m in enumerate(states[:4]):
        assert m.step == k
        np.testing.assert_array_equal(np.stack([m.x, m.y], -1), ref.observe().x)
        ref.advance(np.full(model.n_elements, 1e-4 * (k + 1)))
    answer[0] = False
    n = len(states)
    assert spin_until(ex, lambda: len(states) >= n + 3, timeout=30)  # (state n - 1 was answered)
    # every step since state n - 1 went on without its answer, each counted: as many as the states
    # heard since, less one, or one more when the executor ran the next step before its state's
    # callback (CI, a loaded machine: 3 where 2 were heard)
    extra = len(states) - n
    assert sim.wait.late in (extra - 1, extra), (sim.wait.late, extra)


def test_rod_simulator_builds_markers_only_for_a_subscriber(graph, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The markers (2.5-3.5 ms of the simulator's step in the running graph) are built and
    published every ``marker_period`` only while something subscribes to them (RViz, Foxglove,
    the recorder)."""
    from rclpy.parameter import Parameter
    from visualization_msgs.msg import MarkerArray

    import contgrasp_ros.nodes.rod_simulator as sim_module
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    built: list[int] = []  # (the steps whose markers were built)
    real = sim_module.scene_markers

    def counted(*args):  # type: ignore[no-untyped-def]
        built.append(args[1].k)
        return real(*args)

    monkeypatch.setattr(sim_module, "scene_markers", counted)
    ctx, ex, add = graph
    over = dict(n_elements=6, lockstep=False, control_period=0.02, couple_timeout=0.01, couple_wait=0.0,
                marker_period=0.02, duration=100.0, min_subscribers=1, wait_for_peers=False)
    add(RodSimulator(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in over.items()]))
    probe = add(rclpy.create_node("probe", context=ctx))
    states: list[RodState] = []
    probe.create_subscription(RodState, topics.ROD_STATE, states.append, qos.STREAM)
    assert spin_until(ex, lambda: len(states) >= 5, timeout=30)
    assert built == []
    markers: list[MarkerArray] = []
    probe.create_subscription(MarkerArray, topics.MARKERS, markers.append, qos.STREAM)
    assert spin_until(ex, lambda: len(markers) >= 3, timeout=30)
    assert len(built) >= 3 and [len(m.markers) for m in markers[:3]] == [3, 3, 3]


def test_rod_simulator_free_running_starts_without_a_couple_after_the_timeout(graph) -> None:  # type: ignore[no-untyped-def]
    ex, _, _, states = _free_running(graph, couple_timeout=0.2)
    assert spin_until(ex, lambda: len(states) >= 5, timeout=20)
    assert [m.step for m in states[-3:]] == sorted(m.step for m in states[-3:])


def test_boundary_sensor_senses_a_state_that_arrived_before_the_object(graph) -> None:  # type: ignore[no-untyped-def]
    """The latched object can arrive after the first rod state; that state is sensed then."""
    ctx, ex, add = graph
    sensor = add(BoundarySensor(context=ctx))
    probe = add(rclpy.create_node("probe", context=ctx))
    rod_pub = probe.create_publisher(RodState, topics.ROD_STATE, qos.STREAM)
    got: list[ContactState] = []
    probe.create_subscription(ContactState, topics.CONTACT, got.append, qos.STREAM)
    assert spin_until(ex, lambda: rod_pub.get_subscription_count() > 0 and probe.count_publishers(topics.CONTACT) > 0)
    obj = circle(0.025, (0.08, 0.08))
    shape = arm_near(obj, BasePose(0.0, 0.0, 0.0))
    rod_pub.publish(rod_msg(0, shape, 0.01, 0.0))
    assert spin_until(ex, lambda: sensor.waiting is not None)
    assert got == []
    obj_pub = probe.create_publisher(ObjectBoundary, topics.OBJECT, qos.LATCHED)
    obj_pub.publish(boundary_to_msg(obj, Header(frame_id="world")))
    assert spin_until(ex, lambda: len(got) == 1)
    assert got[0].step == 0 and sensor.drops.total == 0
    np.testing.assert_array_equal(got[0].rho, sense(shape, obj, 0.01).rho)


@pytest.mark.heavy
def test_the_light_nodes_and_the_launcher_import_neither_scipy_nor_the_rod_engine() -> None:
    """Start-up (docs/design.md section 8): only the simulator needs scipy, numba and the rod
    integrator; the sensor, controller and quality processes and the launcher import none of them
    (each would cost those processes ~0.3 s of start-up on a shared core)."""
    code = (
        "import json, sys\n"
        "import contgrasp_ros.launcher.cli, contgrasp_ros.launcher.graph_run\n"
        "import contgrasp_ros.nodes.boundary_sensor, contgrasp_ros.nodes.grasp_controller, contgrasp_ros.nodes.grasp_quality\n"
        "heavy = ('scipy', 'numba', 'matplotlib')\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in heavy or m == 'contgrasp_core.rod.integrator')))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          cwd=Path(__file__).resolve().parents[1], env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads(proc.stdout) == []
