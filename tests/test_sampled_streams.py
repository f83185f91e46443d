"""The observers' sampled streams (``/contgrasp/rod_state/sampled``, ``/contgrasp/contact/sampled``):
the simulator samples its states every ``sample_period`` of simulated time, the first and the
final state always; the sensor republishes the contact states of exactly those steps, whichever
of the two messages reaches it first (docs/ros.md, "How fast")."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

from std_msgs.msg import Header  # noqa: E402

from contgrasp_msgs.msg import ContactState, RodState  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from contgrasp_core.boundary import circle  # noqa: E402
from contgrasp_ros.plumbing.convert import boundary_to_msg, couple_to_msg  # noqa: E402

from conftest import Sink  # noqa: E402

OBJ = circle(0.025, (0.08, 0.08))


def run_small_sim(make, **params):  # type: ignore[no-untyped-def]
    """A 6-element lock-step simulator run to its end with zero couples: (per-step, sampled) messages."""
    from contgrasp_ros.nodes.rod_simulator import RodSimulator, _stamp

    sim = make(RodSimulator, n_elements=6, control_period=0.002, duration=0.021, marker_period=0.0,
               wait_for_peers=False, start_paused=True, **params)
    sim.pub_state, sim.pub_sampled = Sink(RodState), Sink(RodState)
    sim.on_pause(SetBool.Request(data=False), SetBool.Response())
    for _ in range(100):
        if sim.session.finished:
            break
        obs = sim.session.observe()
        sim.on_couple(couple_to_msg(sim.model.joint_s, np.zeros(6), Header(stamp=_stamp(obs.t)), obs.k))
    assert sim.session.finished and not sim.failure and sim.drops.total == 0
    return sim, sim.pub_state.msgs, sim.pub_sampled.msgs


def test_simulator_samples_every_period_and_the_first_and_final_state(make) -> None:  # type: ignore[no-untyped-def]
    sim, states, sampled = run_small_sim(make, sample_period=0.006)
    assert [m.step for m in states] == list(range(12))  # duration 0.021 s in 2 ms steps: states 0..11
    assert [m.step for m in sampled] == [0, 3, 6, 9, 11]  # t = 0, 6, 12, 18 ms and the final state (22 ms)
    assert all(any(m == s for s in states) for m in sampled)  # the same messages as on the per-step stream


def test_sample_period_zero_samples_every_state(make) -> None:  # type: ignore[no-untyped-def]
    _, states, sampled = run_small_sim(make, sample_period=0.0)
    assert [m.step for m in sampled] == [m.step for m in states] == list(range(12))


def test_sensor_republishes_the_contact_of_each_sampled_step_whichever_arrives_first(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor

    sim, states, _ = run_small_sim(make, sample_period=0.006)
    sensor = make(BoundarySensor)
    sensor.pub, sensor.pub_sampled = Sink(ContactState), Sink(ContactState)
    sensor.object.on_object(boundary_to_msg(OBJ, Header()))
    by_step = {m.step: m for m in states}

    def sampled_steps() -> list[int]:
        return [m.step for m in sensor.pub_sampled.msgs]

    sensor.on_rod_state(by_step[0])
    sensor.on_sampled(by_step[0])  # after its state was sensed: at once
    assert sampled_steps() == [0] and sensor.pub_sampled.msgs[0] == sensor.pub.msgs[0]
    sensor.on_sampled(by_step[3])  # before its state: once it is sensed
    for k in (1, 2):
        sensor.on_rod_state(by_step[k])
    assert sampled_steps() == [0]
    sensor.on_rod_state(by_step[3])
    assert sampled_steps() == [0, 3] and sensor.pub_sampled.msgs[-1] == sensor.pub.msgs[-1]
    for k in (5, 6):
        sensor.on_rod_state(by_step[k])
    sensor.on_sampled(by_step[5])  # after the next state too (its executor took the per-step topic first)
    assert sampled_steps() == [0, 3, 5] and sensor.pub_sampled.msgs[-1] == sensor.pub.msgs[-2]
    sensor.on_sampled(by_step[8])  # state 8 is lost on the way: nothing for step 8, later ones still work
    sensor.on_rod_state(by_step[9])
    sensor.on_sampled(by_step[9])
    assert sampled_steps() == [0, 3, 5, 9]
    sensor.on_sampled(by_step[4])  # a state it never sensed, older than the newest: nothing
    assert sampled_steps() == [0, 3, 5, 9]
    sensor.on_sampled(by_step[0])  # a new run (the simulator's reset): its step 0 before its state
    sensor.on_rod_state(by_step[0])
    assert sampled_steps() == [0, 3, 5, 9, 0]
    assert [m.step for m in sensor.pub.msgs] == [0, 1, 2, 3, 5, 6, 9, 0] and sensor.drops.total == 0
    bad = RodState(step=3)  # an announcement with an invalid stamp: dropped and counted, nothing published
    bad.header.stamp.nanosec = 2_000_000_000
    sensor.on_sampled(bad)
    assert sensor.drops.counts == {"/contgrasp/rod_state/sampled: invalid stamp": 1}
    assert sampled_steps() == [0, 3, 5, 9, 0]
