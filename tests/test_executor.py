"""LeanExecutor (contgrasp_ros.plumbing.executor) does what rclpy's executors do, with real rclpy entities:
subscriptions, timers, services and clients, coroutine callbacks and tasks, QoS events,
entities created and destroyed while spinning, exceptions out of callbacks, shutdown."""

from __future__ import annotations

import time
from typing import Any

import pytest

pytest.importorskip("rclpy")

from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import Int32  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from conftest import spin_until  # noqa: E402

from contgrasp_ros.plumbing.executor import EVENTS_PERIOD_S, LeanExecutor  # noqa: E402


@pytest.fixture
def lean(ros_context):  # type: ignore[no-untyped-def]
    import rclpy

    ex = LeanExecutor(context=ros_context)
    nodes: list[Any] = []

    def node(name: str) -> Any:
        n = rclpy.create_node(name, context=ros_context)
        nodes.append(n)
        ex.add_node(n)
        return n

    yield ex, node
    ex.shutdown()
    for n in nodes:
        n.destroy_node()


def test_messages_timers_and_entities_made_and_destroyed_while_spinning(lean) -> None:  # type: ignore[no-untyped-def]
    ex, node = lean
    a, b = node("a"), node("b")
    pub = a.create_publisher(Int32, "/lean/x", 100)
    got: list[int] = []
    sub = b.create_subscription(Int32, "/lean/x", lambda m: got.append(m.data), 100)
    ticks: list[float] = []
    b.create_timer(0.01, lambda: ticks.append(time.monotonic()))
    assert spin_until(ex, lambda: pub.get_subscription_count() == 1)
    for i in range(50):
        pub.publish(Int32(data=i))
    assert spin_until(ex, lambda: len(got) == 50)
    assert got == list(range(50))  # every message (one taken per subscription and wait), in order
    assert spin_until(ex, lambda: len(ticks) >= 5)
    # a subscription made while spinning joins the wait set; one destroyed leaves it
    late: list[int] = []
    b.create_subscription(Int32, "/lean/x", lambda m: late.append(m.data), 10)
    assert spin_until(ex, lambda: pub.get_subscription_count() == 2)
    b.destroy_subscription(sub)
    pub.publish(Int32(data=99))
    assert spin_until(ex, lambda: late == [99])
    assert got == list(range(50))


def test_services_clients_coroutines_and_tasks(lean) -> None:  # type: ignore[no-untyped-def]
    ex, node = lean
    server, caller = node("server"), node("caller")

    def answer(req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        resp.success, resp.message = req.data, "yes" if req.data else "no"
        return resp

    server.create_service(SetBool, "/lean/ask", answer)
    client = caller.create_client(SetBool, "/lean/ask")
    assert spin_until(ex, client.service_is_ready)
    fut = client.call_async(SetBool.Request(data=True))
    ex.spin_until_future_complete(fut, timeout_sec=10.0)
    assert fut.done() and fut.result().message == "yes"

    # a coroutine callback that awaits a service call is resumed when the answer comes
    answers: list[str] = []

    async def on_msg(msg: Int32) -> None:
        resp = await client.call_async(SetBool.Request(data=msg.data > 0))
        answers.append(resp.message)

    pub = caller.create_publisher(Int32, "/lean/y", 10)
    server.create_subscription(Int32, "/lean/y", on_msg, 10)
    assert spin_until(ex, lambda: pub.get_subscription_count() == 1)
    pub.publish(Int32(data=1))
    pub.publish(Int32(data=0))
    assert spin_until(ex, lambda: len(answers) == 2)
    assert answers == ["yes", "no"]

    task = ex.create_task(lambda: 6 * 7)
    assert spin_until(ex, task.done) and task.result() == 42


def test_an_exception_in_a_callback_leaves_spin_once(lean) -> None:  # type: ignore[no-untyped-def]
    ex, node = lean
    n = node("boom")
    n.create_timer(0.01, lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        spin_until(ex, lambda: False, timeout=5.0)


def test_qos_events_reach_their_handlers(lean) -> None:  # type: ignore[no-untyped-def]
    """A best-effort publisher cannot serve a reliable subscription: rclpy's default handler
    for incompatible QoS is a waitable the executor looks at every EVENTS_PERIOD_S."""
    from rclpy.event_handler import SubscriptionEventCallbacks

    ex, node = lean
    a, b = node("offer"), node("request")
    seen: list[Any] = []
    b.create_subscription(Int32, "/lean/q", lambda m: None, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE),
                          event_callbacks=SubscriptionEventCallbacks(incompatible_qos=seen.append))
    a.create_publisher(Int32, "/lean/q", QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
    assert spin_until(ex, lambda: len(seen) > 0, timeout=10.0)
    assert seen[0].total_count >= 1


def test_a_blocking_wait_still_looks_at_events_and_ends_at_shutdown(lean) -> None:  # type: ignore[no-untyped-def]
    ex, node = lean
    node("idle")
    t0 = time.monotonic()
    ex.spin_once(timeout_sec=5.0)  # nothing to do: the wait ends for the next look at the QoS events
    assert time.monotonic() - t0 < 5.0
    ex.shutdown()
    t0 = time.monotonic()
    ex.spin_once(timeout_sec=5.0)  # a shut-down executor returns at once
    assert time.monotonic() - t0 < 1.0
    assert EVENTS_PERIOD_S < 1.0


def test_an_entity_destroyed_by_a_callback_in_the_same_turn_is_skipped(lean) -> None:  # type: ignore[no-untyped-def]
    """Two subscriptions ready after one wait; the first callback destroys the second and a
    timer: the turn goes on without them, and the next turn waits on what is left."""
    ex, node = lean
    a, b = node("src"), node("dst")
    pub = a.create_publisher(Int32, "/lean/z", 10)
    got: list[str] = []
    victims: dict[str, Any] = {}

    def first(m: Int32) -> None:
        got.append(f"first {m.data}")
        if "sub" in victims:
            b.destroy_subscription(victims.pop("sub"))
            b.destroy_timer(victims.pop("timer"))

    b.create_subscription(Int32, "/lean/z", first, 10)
    victims["sub"] = b.create_subscription(Int32, "/lean/z", lambda m: got.append(f"second {m.data}"), 10)
    victims["timer"] = b.create_timer(0.001, lambda: got.append("tick"))
    assert spin_until(ex, lambda: pub.get_subscription_count() == 2)
    got.clear()
    pub.publish(Int32(data=1))
    time.sleep(0.05)  # (both subscriptions and the timer ready for the same wait)
    assert spin_until(ex, lambda: any(g.startswith("first") for g in got))
    pub.publish(Int32(data=2))
    assert spin_until(ex, lambda: "first 2" in got)
    assert "second 1" not in got and "second 2" not in got  # (skipped in the turn it was destroyed in, then gone)
    assert "tick" not in got  # (messages run first in a turn: the timer is destroyed before its turn came)


def test_messages_run_before_timers_in_a_turn(lean) -> None:  # type: ignore[no-untyped-def]
    """A message and a due timer ready after one wait: the message's callback runs first, so a
    periodic step sees the input that arrived with it (the free-running simulator's couple)."""
    ex, node = lean
    a, b = node("src"), node("dst")
    pub = a.create_publisher(Int32, "/lean/order", 10)
    got: list[str] = []
    b.create_subscription(Int32, "/lean/order", lambda m: got.append(f"message {m.data}"), 10)
    b.create_timer(0.001, lambda: got.append("tick"))
    assert spin_until(ex, lambda: pub.get_subscription_count() == 1)
    got.clear()
    pub.publish(Int32(data=7))
    time.sleep(0.05)  # (the message and the timer both ready for the next wait)
    ex.spin_once(timeout_sec=1.0)
    assert got[:2] == ["message 7", "tick"]
