"""Reliability of the nodes: hostile messages, unexpected exceptions, diagnostics, parameter
refusal and simulator divergence (docs/ros.md, Reliability).

The message handlers are called directly on real rclpy nodes (``node.on_rod_state(msg)``);
outputs are caught by replacing the node's publisher. Every property test checks that no
exception escapes and that each message is either processed (a valid output published / the
rod advanced) or counted as exactly one drop with a reason - never as an internal error.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

rclpy = pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from contgrasp_core.arm import BasePose, shape_from_curvature  # noqa: E402
from contgrasp_core.boundary import circle  # noqa: E402
from contgrasp_core.contact import sense  # noqa: E402
from contgrasp_core.rod import RodModel  # noqa: E402
from contgrasp_core.rod.integrator import StepFailedError  # noqa: E402
from contgrasp_msgs.msg import ContactState, CoupleControl, ObjectBoundary, RodState  # noqa: E402
from contgrasp_ros.plumbing import qos, topics  # noqa: E402
from contgrasp_ros.plumbing.convert import MAX_SAMPLES, boundary_to_msg  # noqa: E402
from contgrasp_ros.plumbing.stamps import stamp_problem  # noqa: E402

from conftest import Sink, fresh_domain_id  # noqa: E402

OBJ = circle(0.025, (0.08, 0.08))
NS = 1_000_000_000
PROPERTY = settings(max_examples=60, deadline=None)


# ---------------------------------------------------------------------------- hostile messages
CORRUPTIONS = ("none", "none", "none", "shorten", "lengthen", "empty", "nan", "inf", "huge", "large", "too many", "grid")
STAMPS = ("next", "next", "next", "past", "reset", "future", "invalid")
values = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.floats(-1.0, 1.0))


@st.composite
def corruption(draw: Callable[..., Any], fields: tuple[str, ...]) -> tuple[str, str, int, float]:
    """(kind, field, index seed, value) of at most one corruption of a message's arrays."""
    return (draw(st.sampled_from(CORRUPTIONS)), draw(st.sampled_from(fields)), draw(st.integers(0, 10**6)), draw(values))


def corrupt(arrays: dict[str, list[float]], how: tuple[str, str, int, float]) -> str:
    """Apply the corruption in place; returns its kind ("none" when it left the arrays valid)."""
    kind, field, seed, value = how
    arr = arrays[field]
    if kind in ("shorten", "lengthen", "nan", "inf", "huge", "large", "grid") and not arr:
        return "none"  # (an empty optional field stays valid)
    if kind == "shorten":
        arrays[field] = arr[:-1] if len(arr) > 0 else arr
    elif kind == "lengthen":
        arrays[field] = [*arr, value]
    elif kind == "empty":
        for k in arrays:
            arrays[k] = []
    elif kind in ("nan", "inf", "huge", "large"):  # (large: extreme but within the accepted magnitudes)
        arr[seed % len(arr)] = {"nan": math.nan, "inf": -math.inf, "huge": 1e300, "large": -9e5}[kind]
    elif kind == "too many":
        for k in arrays:
            arrays[k] = [0.0] * (MAX_SAMPLES + 1)
    elif kind == "grid":
        if "s" not in arrays or len(arrays["s"]) < 2:
            return "none"
        arrays["s"][0], arrays["s"][1] = arrays["s"][1], arrays["s"][0]
    return kind


def make_stamp(kind: str, newest_ns: int | None, frac: float, next_ns: int) -> tuple[int, int, str | None, bool]:
    """(sec, nanosec, expected drop reason, step-0) of a stamp of the given kind, given the
    node's newest accepted stamp; ``next_ns`` is a fresh stamp later than everything so far."""
    if kind == "future":
        return int(time.time()) + 1000, 0, "from the future", False
    if kind == "invalid":
        return 3, NS + int(frac * 1e9), "invalid stamp", False
    if kind in ("past", "reset") and newest_ns:
        t = int(newest_ns * frac)
        return t // NS, t % NS, ("from the past" if kind == "past" else None), kind == "reset"
    return next_ns // NS, next_ns % NS, None, False


class Expect:
    """Checks one delivery: the handler returned, and exactly one of processed / dropped."""

    def __init__(self, drops: Any, processed: Callable[[], int]) -> None:
        self.drops, self.processed = drops, processed
        self.outcomes = {True: 0, False: 0}

    def deliver(self, handler: Callable[[Any], None], msg: Any) -> tuple[bool, str | None]:
        before, n_before = dict(self.drops.counts), self.processed()
        handler(msg)  # must not raise
        new = [k for k in self.drops.counts if self.drops.counts[k] != before.get(k, 0)]
        done = self.processed() - n_before
        assert (done, len(new)) in ((1, 0), (0, 1)), (done, new)
        assert not any("internal error" in k for k in new), new
        self.outcomes[not new] += 1
        if new:
            assert self.drops.counts[new[0]] == before.get(new[0], 0) + 1
            return False, new[0].split(": ", 1)[1]
        return True, None


def check_outcome(ok: bool, reason: str | None, bad_content: str, stamp_reason: str | None) -> None:
    if bad_content == "large":
        return  # valid or not (e.g. it breaks the arclength grid): either outcome, never an internal error
    if bad_content != "none":
        assert not ok, f"accepted a message with corruption {bad_content}"
    elif stamp_reason is not None:
        assert reason == stamp_reason
    else:
        assert ok, f"a valid message was dropped: {reason}"


def rod_arrays(n: int, curv: float, base: tuple[float, float, float]) -> dict[str, list[float]]:
    shape = shape_from_curvature(np.linspace(0.0, 0.2, n), np.full(n, curv), BasePose(*base))
    return {"s": shape.s.tolist(), "x": shape.r[:, 0].tolist(), "y": shape.r[:, 1].tolist(), "theta": shape.theta.tolist(),
            "kappa": [], "radius": np.linspace(0.01, 0.001, n).tolist()}


poses = st.tuples(st.floats(-0.1, 0.1), st.floats(-0.1, 0.1), st.floats(-3.0, 3.0))


def test_boundary_sensor_survives_hostile_rod_states(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor

    node = make(BoundarySensor)
    node.pub = Sink(ContactState)
    node.object.on_object(boundary_to_msg(OBJ, Header()))
    assert node.object.boundary is not None
    expect = Expect(node.drops, lambda: len(node.pub.msgs))
    clock = [NS]

    @PROPERTY
    @given(n=st.integers(2, 40), curv=st.floats(0.0, 40.0), pose=poses, how=corruption(tuple(rod_arrays(2, 0, (0, 0, 0)))),
           stamp=st.sampled_from(STAMPS), frac=st.floats(0.0, 0.999), step=st.integers(1, 2**40))
    def prop(n, curv, pose, how, stamp, frac, step) -> None:  # type: ignore[no-untyped-def]
        arrays = rod_arrays(n, curv, pose)
        bad = corrupt(arrays, how)
        clock[0] += 10_000_000
        sec, nsec, stamp_reason, reset = make_stamp(stamp, node.stamps.newest_ns.get(topics.ROD_STATE), frac, clock[0])
        step = max(step, node.stamps.newest_step.get(topics.ROD_STATE, 0))  # (a lower step starts a new run)
        msg = RodState(step=0 if reset else step, **arrays)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
        ok, reason = expect.deliver(node.on_rod_state, serialize_message(msg))  # (as its raw subscription gets it)
        check_outcome(ok, reason, bad, stamp_reason)
        if ok:
            out = node.pub.msgs[-1]
            assert out.step == msg.step and out.header.stamp == msg.header.stamp and len(out.rho) == n
            assert np.all(np.isfinite(out.rho)) and np.all(np.isfinite(out.alpha)) and np.all(np.isfinite(out.s_o))

    prop()
    assert expect.outcomes[True] > 0 and expect.outcomes[False] > 0 and node.sensed == expect.outcomes[True]


def contact_arrays_of(n: int, curv: float, pose: tuple[float, float, float]) -> tuple[dict[str, list[float]], list[bool], float]:
    shape = shape_from_curvature(np.linspace(0.0, 0.2, n), np.full(n, curv), BasePose(*pose))
    c = sense(shape, OBJ, np.linspace(0.01, 0.001, n), tol=0.001)
    arrays = {"s": c.s.tolist(), "rho": c.rho.tolist(), "alpha": c.alpha.tolist(), "delta": c.delta.tolist(),
              "s_o": c.s_o.tolist(), "shadow_x": c.foot[:, 0].tolist(), "shadow_y": c.foot[:, 1].tolist()}
    return arrays, [bool(v) for v in c.in_contact], c.tol


CONTACT_FIELDS = ("s", "rho", "alpha", "delta", "s_o", "shadow_x", "shadow_y", "in_contact")


def hostile_contact(n: int, curv: float, pose: tuple[float, float, float], how: tuple[str, str, int, float]) -> tuple[dict[str, Any], str]:
    arrays, flags, tol = contact_arrays_of(n, curv, pose)
    if how[1] == "in_contact":  # the flags: only their length can be wrong
        bad = how[0] if how[0] in ("shorten", "lengthen") else "none"
        flags = flags[:-1] if bad == "shorten" else [*flags, True] if bad == "lengthen" else flags
    else:
        bad = corrupt(arrays, how)
        if bad in ("empty", "too many"):
            flags = [False] * len(arrays["s"])
    return {**arrays, "in_contact": flags, "contact_tolerance": tol}, bad


def test_grasp_controller_survives_hostile_contact_states(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.grasp_controller import GraspController

    n_el = 8
    node = make(GraspController, n_elements=n_el)
    node.pub = Sink(CoupleControl)
    expect = Expect(node.drops, lambda: len(node.pub.msgs))
    clock = [NS]

    @PROPERTY
    @given(n=st.sampled_from([n_el + 1] * 4 + [2, 5, 30]), curv=st.floats(0.0, 40.0), pose=poses, how=corruption(CONTACT_FIELDS),
           stamp=st.sampled_from(STAMPS), frac=st.floats(0.0, 0.999), step=st.integers(1, 2**40))
    def prop(n, curv, pose, how, stamp, frac, step) -> None:  # type: ignore[no-untyped-def]
        fields, bad = hostile_contact(n, curv, pose, how)
        if bad == "none" and n != n_el + 1:
            bad = "wrong node count"
        clock[0] += 10_000_000
        sec, nsec, stamp_reason, reset = make_stamp(stamp, node.stamps.newest_ns.get(topics.CONTACT), frac, clock[0])
        step = max(step, node.stamps.newest_step.get(topics.CONTACT, 0))  # (a lower step starts a new run)
        msg = ContactState(step=0 if reset else step, **fields)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
        ok, reason = expect.deliver(node.on_contact, serialize_message(msg))  # (as its raw subscription gets it)
        check_outcome(ok, reason, bad, stamp_reason)
        if bad == "wrong node count":
            assert reason == "wrong node count"
        if ok:
            out = node.pub.msgs[-1]
            assert out.step == msg.step and len(out.u) == n_el and np.all(np.isfinite(out.u))

    prop()
    assert expect.outcomes[True] > 0 and expect.outcomes[False] > 0


def test_grasp_quality_survives_hostile_contact_states(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.grasp_quality import GraspQualityNode

    node = make(GraspQualityNode, rate_hz=0.0)
    node.pub = Sink()
    # a contact state before the object is kept (not dropped) and evaluated once the object is there
    node.on_contact(ContactState(**contact_arrays_of(5, 10.0, (0, 0, 0))[0], in_contact=[False] * 5))
    assert node.waiting is not None and node.drops.total == 0 and node.pub.msgs == []
    node.object.on_object(boundary_to_msg(OBJ, Header()))
    assert node.waiting is None and len(node.pub.msgs) == 1 and node.drops.total == 0
    expect = Expect(node.drops, lambda: len(node.pub.msgs))
    clock = [NS]

    @PROPERTY
    @given(n=st.integers(2, 40), curv=st.floats(0.0, 40.0), pose=poses, how=corruption(CONTACT_FIELDS),
           stamp=st.sampled_from(STAMPS), frac=st.floats(0.0, 0.999), step=st.integers(1, 2**40))
    def prop(n, curv, pose, how, stamp, frac, step) -> None:  # type: ignore[no-untyped-def]
        fields, bad = hostile_contact(n, curv, pose, how)
        clock[0] += 10_000_000
        sec, nsec, stamp_reason, reset = make_stamp(stamp, node.stamps.newest_ns.get(topics.CONTACT_SAMPLED), frac, clock[0])
        step = max(step, node.stamps.newest_step.get(topics.CONTACT_SAMPLED, 0))  # (a lower step starts a new run)
        msg = ContactState(step=0 if reset else step, **fields)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
        ok, reason = expect.deliver(node.on_contact, msg)
        check_outcome(ok, reason, bad, stamp_reason)
        if ok:
            out = node.pub.msgs[-1]
            assert out.step == msg.step and np.all(np.isfinite(out.w)) and 0.0 <= out.q3 <= 1.0

    prop()
    assert expect.outcomes[True] > 0 and expect.outcomes[False] > 0


COUPLE_FIELDS = ("s", "u", "rho_ref", "alpha_ref", "du_drho", "du_dalpha")


def small_sim(make, **params):  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    # (no graph around it: step 0 goes out at once instead of waiting for a sensor and a controller)
    p = dict(n_elements=6, damping=2.0, drag_normal=5110.0, drag_tangential=25.55, duration=100.0, marker_period=0.0,
             wait_for_peers=False)
    p.update(params)
    return make(RodSimulator, **p)


def test_rod_simulator_survives_hostile_couples(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.rod_simulator import _stamp

    sim = small_sim(make)
    n = sim.model.n_elements
    stamps: dict[int, Any] = {}  # step -> the stamp of the state published for it

    applied = [0]  # couples the simulator applied (a step; an absurd but finite couple may then fail the run)
    advance = sim._advance

    def counting_advance(u: Any) -> None:
        applied[0] += 1
        advance(u)

    sim._advance = counting_advance

    def progress() -> int:
        return applied[0]

    expect = Expect(sim.drops, progress)

    @PROPERTY
    @given(u=st.lists(st.floats(-1e-5, 1e-5), min_size=n, max_size=n), expansion=st.booleans(), how=corruption(COUPLE_FIELDS),
           stamp=st.sampled_from(STAMPS + ("stale",)), frac=st.floats(0.0, 0.999), wrong_step=st.integers(-3, 3))
    def prop(u, expansion, how, stamp, frac, wrong_step) -> None:  # type: ignore[no-untyped-def]
        if sim.failure or sim.session.k > 40:
            sim.on_reset(Trigger.Request(), Trigger.Response())
        k = sim.session.k
        stamps[k] = _stamp(float(sim.session.state.t))
        arrays = {"s": sim.model.joint_s.tolist(), "u": u}
        arrays.update({f: (np.full(n, 0.5 if f == "alpha_ref" else 1e-7).tolist() if expansion else []) for f in COUPLE_FIELDS[2:]})
        bad = corrupt(arrays, how)
        if bad in ("huge", "large") and how[1] != "s":
            bad = "none"  # a huge but finite couple is valid content: it may break the run (failed)
        step = k
        if stamp == "stale":
            step = max(0, k + wrong_step)
            stamp_reason = None if step == k else "step mismatch"
            t_ns = stamps[k].sec * NS + stamps[k].nanosec
            sec, nsec = t_ns // NS, t_ns % NS
        else:
            newest = sim.stamps.newest_ns.get(topics.COUPLE)
            sec, nsec, stamp_reason, reset = make_stamp(stamp, newest, frac, stamps[k].sec * NS + stamps[k].nanosec)
            if reset:  # step 0 is only the current step right after a reset
                step, stamp_reason = 0, (None if k == 0 else "step mismatch")
        msg = CoupleControl(step=step, **arrays)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
        if bad == "none" and sim.model.n_elements != len(arrays["u"]):
            bad = "wrong joints"
        ok, reason = expect.deliver(sim.on_couple, serialize_message(msg))  # (as its raw subscription gets it)
        check_outcome(ok, reason, bad, stamp_reason)

    prop()
    assert expect.outcomes[True] > 0 and expect.outcomes[False] > 0


def test_rod_simulator_applies_a_hold_and_drops_one_made_for_another_rod(make) -> None:  # type: ignore[no-untyped-def]
    """The holding law's hold (kappa_ref, hold_gain): one whose couple u is not -EI kappa_ref of
    this rod is dropped and counted, and the run does not advance; a consistent one is applied
    (one step), and its ``transition`` flag is what the next state's settle check gets."""
    sim = small_sim(make)
    m = sim.model
    kappa_ref = np.full(m.n_elements, 2.0)

    def hold(u: np.ndarray, step: int) -> bytes:
        msg = CoupleControl(step=step, s=m.joint_s.tolist(), u=u.tolist(), kappa_ref=kappa_ref.tolist(), hold_gain=10.0,
                            transition=True)
        msg.header.stamp.sec, msg.header.stamp.nanosec = 0, 0
        return serialize_message(msg)

    sim.on_couple(hold(-2.0 * m.joint_ei * kappa_ref, 0))  # (twice the stiffness: another rod's hold)
    assert sim.drops.counts == {"/contgrasp/couple: inconsistent hold": 1} and sim.session.k == 0
    sim.on_couple(hold(-m.joint_ei * kappa_ref, 0))
    assert sim.session.k == 1 and sim.drops.total == 1 and not sim.law_ready


@st.composite
def outlines(draw: Callable[..., Any]) -> tuple[list[float], list[float]]:
    kind = draw(st.sampled_from(["random", "polygon", "bowtie", "collinear", "duplicate", "mismatch"]))
    if kind == "random":
        pts = draw(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), max_size=12))
        return [p[0] for p in pts], [p[1] for p in pts]
    m = draw(st.integers(5, 40))
    a = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    x, y = 0.08 + 0.03 * np.cos(a), 0.08 + 0.02 * np.sin(a)
    if kind == "bowtie":
        x, y = np.array([0.0, 1.0, 0.0, 1.0, 0.5]), np.array([0.0, 1.0, 1.0, 0.0, -0.5])
    elif kind == "collinear":
        x, y = np.linspace(0, 1, m), np.linspace(0, 2, m)
    elif kind == "duplicate":
        x, y = np.full(m, 0.3), np.full(m, -0.1)
    elif kind == "mismatch":
        y = y[:-1]
    return x.tolist(), y.tolist()


VALID_SPECS = {
    "circle": {"R": 0.03, "center_x": 0.08, "center_y": 0.08},
    "ellipse": {"a": 0.04, "b": 0.02, "center_x": 0.08, "center_y": 0.06, "angle": 0.3},
    "deformed_circle": {"R": 0.03, "amplitude": 0.1, "lobes": 3.0, "phase": 0.0, "center_x": 0.0, "center_y": 0.1},
}
PARAM_NAMES = ["R", "a", "b", "center_x", "center_y", "angle", "amplitude", "lobes", "phase", "", "R "]


@st.composite
def objects(draw: Callable[..., Any]) -> ObjectBoundary:
    """Valid analytic objects (possibly with one hostile parameter), outlines (valid, crossing,
    degenerate, mismatched) and random junk."""
    mode = draw(st.sampled_from(["analytic", "analytic", "outline", "junk"]))
    if mode == "analytic":
        kind = draw(st.sampled_from(sorted(VALID_SPECS)))
        params = dict(VALID_SPECS[kind])
        if draw(st.booleans()):  # one hostile value or a missing name
            name = draw(st.sampled_from(sorted(params)))
            if draw(st.booleans()):
                params[name] = draw(values)
            else:
                del params[name]
        return ObjectBoundary(kind=kind, parameter_names=list(params), parameter_values=list(params.values()))
    if mode == "outline":
        x, y = draw(outlines())
        return ObjectBoundary(kind=draw(st.sampled_from(["points", "fourier_polar", ""])), x=x, y=y)
    names = draw(st.lists(st.sampled_from(PARAM_NAMES), max_size=9))
    vals = draw(st.lists(values, min_size=len(names), max_size=len(names) + 1))
    x, y = draw(outlines())
    return ObjectBoundary(kind=draw(st.sampled_from(["circle", "ellipse", "deformed_circle", "points", "nonsense"])),
                          parameter_names=names, parameter_values=vals, x=x, y=y)


@pytest.mark.parametrize("which", ["sensor", "quality"])
def test_object_tracker_survives_hostile_objects(make, which) -> None:  # type: ignore[no-untyped-def]
    node = make(_node_classes()[which])
    tracker = node.object
    accepted = [0]
    original = tracker._on_change

    def on_change() -> None:  # count, then what the node does with a new object
        accepted[0] += 1
        if original is not None:
            original()

    tracker._on_change = on_change
    expect = Expect(node.drops, lambda: accepted[0])

    @PROPERTY
    @given(msg=objects(), stamp=st.sampled_from(["ok", "ok", "future", "invalid", "old"]))
    def prop(msg, stamp) -> None:  # type: ignore[no-untyped-def]
        sec, nsec = {"ok": (5, 0), "future": (int(time.time()) + 1000, 0), "invalid": (5, 2 * NS), "old": (0, 0)}[stamp]
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
        before = tracker.boundary
        ok, reason = expect.deliver(tracker.on_object, msg)
        if ok:
            assert tracker.boundary is not before and np.isfinite(tracker.boundary.length)
            assert stamp in ("ok", "old")  # the object has no step: an older stamp is accepted
        else:
            assert tracker.boundary is before
            if reason in ("from the future", "invalid stamp"):
                assert reason == {"future": "from the future", "invalid": "invalid stamp"}[stamp]

    prop()
    tracker._on_change = original
    assert expect.outcomes[True] > 0 and expect.outcomes[False] > 0


def test_self_intersecting_object_is_dropped_with_its_reason(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor

    node = make(BoundarySensor)
    node.object.on_object(boundary_to_msg(OBJ, Header()))
    good = node.object.boundary
    bowtie = ObjectBoundary(kind="points", x=[0.0, 1.0, 1.0, 0.0, 0.5, -0.2], y=[0.0, 1.0, 0.0, 1.0, 1.4, 0.5])
    node.object.on_object(bowtie)
    assert node.drops.counts == {"/contgrasp/object: bad object: SelfIntersectionError": 1}
    assert node.object.boundary is good  # the previous object stays in use


def test_sensor_keeps_only_the_newest_state_while_the_object_is_missing(make) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor

    node = make(BoundarySensor)
    node.pub = Sink(ContactState)
    for step in (1, 2):
        msg = RodState(step=step, **rod_arrays(9, 10.0, (0.0, 0.0, 0.0)))
        msg.header.stamp.sec = step
        node.on_rod_state(msg)
    assert node.drops.counts == {"/contgrasp/rod_state: no object yet": 1} and node.pub.msgs == []
    node.object.on_object(boundary_to_msg(OBJ, Header()))
    assert [m.step for m in node.pub.msgs] == [2]


# ---------------------------------------------------------------------------- the stamp rule
def test_stamp_rule() -> None:
    now = 10 * NS
    assert stamp_problem(5, 0, 3, None, now, 1.0) is None
    assert stamp_problem(5, NS, 3, None, now, 1.0) == "invalid stamp"
    assert stamp_problem(-1, 0, 3, None, now, 1.0) == "invalid stamp"
    assert stamp_problem(11, 0, 3, None, now, 1.0) is None  # exactly max_future ahead
    assert stamp_problem(11, 1, 3, None, now, 1.0) == "from the future"
    assert stamp_problem(1000, 0, 3, None, 0, 1.0) is None  # clock not valid yet (no /clock): no future check
    assert stamp_problem(5, 0, 3, 6 * NS, now, 1.0) == "from the past"
    assert stamp_problem(6, 0, 3, 6 * NS, now, 1.0) is None  # equal stamps are not older
    assert stamp_problem(0, 0, 0, 6 * NS, now, 1.0) is None  # step 0: the simulator was reset
    assert stamp_problem(0, 4, 2, 6 * NS, now, 1.0, newest_step=3) is None  # a lower step: a restarted run
    assert stamp_problem(5, 0, 3, 6 * NS, now, 1.0, newest_step=3) == "from the past"  # same step, older: stale
    assert stamp_problem(5, 0, 3, 6 * NS, now, 1.0, check_past=False) is None


def test_stamp_rule_in_sim_time(make) -> None:  # type: ignore[no-untyped-def]
    """With use_sim_time the future check waits for the first /clock, then uses sim time; a
    step-0 message restarts the past tracking."""
    from rclpy.time import Time

    from contgrasp_ros.nodes.grasp_controller import GraspController

    node = make(GraspController, n_elements=8, use_sim_time=True, max_future_stamp=0.5)
    node.pub = Sink(CoupleControl)
    arrays, flags, tol = contact_arrays_of(9, 10.0, (0.0, 0.0, 0.0))

    def deliver(sec: float, step: int) -> None:
        msg = ContactState(step=step, **arrays, in_contact=flags, contact_tolerance=tol)
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(sec), int(round((sec % 1) * 1e9))
        node.on_contact(msg)

    deliver(100.0, 1)  # no /clock yet: the node clock is 0, the future check is skipped
    assert len(node.pub.msgs) == 1
    node.get_clock().set_ros_time_override(Time(seconds=2.0))  # what the TimeSource does on /clock
    assert node.get_clock().now().nanoseconds == 2 * NS
    deliver(2.4, 2)  # 'from the past' (100 s accepted before)
    deliver(0.0, 0)  # reset: accepted, the tracking restarts
    deliver(2.4, 1)
    deliver(2.6, 2)  # 0.6 s ahead of sim time 2.0: from the future
    assert len(node.pub.msgs) == 3
    assert node.drops.counts == {"/contgrasp/contact: from the past": 1, "/contgrasp/contact: from the future": 1}


# ---------------------------------------------------------------------------- internal errors
def _boom(*_args: object, **_kwargs: object) -> None:
    raise RuntimeError("injected fault")


def test_unexpected_exception_is_counted_and_the_node_keeps_working(make, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A core function raising RuntimeError inside a real subscription callback (through the
    executor): counted as an internal error, the executor keeps spinning, the next state is sensed."""
    from rclpy.executors import SingleThreadedExecutor

    from contgrasp_ros.nodes import boundary_sensor
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor

    node = make(BoundarySensor)
    probe = make(lambda **kw: rclpy.create_node("probe", **kw))
    ex = SingleThreadedExecutor(context=node.context)
    ex.add_node(node)
    ex.add_node(probe)
    got: list[ContactState] = []
    probe.create_subscription(ContactState, topics.CONTACT, got.append, qos.STREAM)
    pub = probe.create_publisher(RodState, topics.ROD_STATE, qos.STREAM)
    node.object.on_object(boundary_to_msg(OBJ, Header()))

    def spin_until(cond: Callable[[], bool]) -> bool:
        end = time.monotonic() + 10
        while time.monotonic() < end and not cond():
            ex.spin_once(timeout_sec=0.02)
        return cond()

    assert spin_until(lambda: pub.get_subscription_count() > 0 and probe.count_publishers(topics.CONTACT) > 0)
    arrays = rod_arrays(11, 10.0, (0.0, 0.0, 0.0))
    monkeypatch.setattr(boundary_sensor, "sense", _boom)
    pub.publish(RodState(step=1, **arrays))
    assert spin_until(lambda: node.drops.total == 1)
    assert node.drops.counts == {"/contgrasp/rod_state: internal error: RuntimeError": 1}
    monkeypatch.undo()
    msg = RodState(step=2, **arrays)
    msg.header.stamp.sec = 1
    pub.publish(msg)
    assert spin_until(lambda: len(got) == 1)
    assert got[0].step == 2
    ex.shutdown()


@pytest.mark.parametrize("which", ["controller", "quality", "simulator", "tracker", "service"])
def test_internal_errors_in_every_handler_are_contained(make, monkeypatch, which) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.plumbing import convert
    from contgrasp_ros.nodes import grasp_controller, grasp_quality, rod_simulator

    arrays, flags, tol = contact_arrays_of(9, 10.0, (0.0, 0.0, 0.0))
    if which == "controller":
        node = make(grasp_controller.GraspController, n_elements=8)
        monkeypatch.setattr(grasp_controller, "feedback_at_joints", _boom)
        node.on_contact(ContactState(step=1, **arrays, in_contact=flags, contact_tolerance=tol))
        key = "/contgrasp/contact: internal error: RuntimeError"
    elif which == "quality":
        node = make(grasp_quality.GraspQualityNode, rate_hz=0.0)
        node.object.on_object(boundary_to_msg(OBJ, Header()))
        monkeypatch.setattr(grasp_quality, "contact_quality", _boom)
        node.on_contact(ContactState(step=1, **arrays, in_contact=flags, contact_tolerance=tol))
        key = "/contgrasp/contact/sampled: internal error: RuntimeError"
    elif which == "tracker":
        node = make(grasp_quality.GraspQualityNode)
        monkeypatch.setattr(convert, "boundary_from_msg", _boom)
        node.object.on_object(boundary_to_msg(OBJ, Header()))
        key = "/contgrasp/object: internal error: RuntimeError"
    elif which == "simulator":
        node = small_sim(make)
        monkeypatch.setattr(rod_simulator, "couple_arrays", _boom)
        node.on_couple(CoupleControl(step=0, s=node.model.joint_s.tolist(), u=[0.0] * 6))
        key = "/contgrasp/couple: internal error: RuntimeError"
    else:
        node = small_sim(make)
        monkeypatch.setattr(node, "_reset_session", _boom)
        resp = node.on_reset(Trigger.Request(), Trigger.Response())
        assert not resp.success and "RuntimeError" in resp.message
        key = "~/reset: internal error: RuntimeError"
    assert node.drops.counts == {key: 1}
    monkeypatch.undo()
    if which in ("controller", "quality"):  # and it works again afterwards
        node.pub = Sink(node.pub.msg_type)
        msg = ContactState(step=2, **arrays, in_contact=flags, contact_tolerance=tol)
        msg.header.stamp.sec = 1
        node.on_contact(msg)
        assert len(node.pub.msgs) == 1
    elif which in ("simulator", "service"):
        node.on_couple(CoupleControl(step=0, s=node.model.joint_s.tolist(), u=[0.0] * 6))
        assert node.session.k == 1


# ---------------------------------------------------------------------------- diagnostics
@pytest.mark.parametrize("with_summary", [True, False])
def test_diagnostics_update_publishes_on_a_change_at_once_and_otherwise_a_few_times_a_second(make, with_summary) -> None:  # type: ignore[no-untyped-def]
    """Diagnostics.update (after every simulator state): the first call publishes; within
    min_period_s only a change of level or message does; with a ``summary`` the values are
    built only for a publication."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor
    from contgrasp_ros.plumbing.diagnostics import Diagnostics

    host = make(BoundarySensor)
    state = {"level": DiagnosticStatus.OK, "message": "running", "built": 0}

    def build() -> tuple[int, str, dict[str, str]]:
        state["built"] += 1
        return state["level"], state["message"], {"step": "1"}

    d = Diagnostics(host, host.drops, build, min_period_s=0.3,
                    summary=(lambda: (state["level"], state["message"])) if with_summary else None)
    d.pub = Sink(DiagnosticArray)

    def published() -> list[tuple[int, str]]:
        return [(m.status[0].level, m.status[0].message) for m in d.pub.msgs]

    d.update()
    d.update()
    assert published() == [(DiagnosticStatus.OK, "running")]
    state["message"] = "paused"
    d.update()
    state["level"] = DiagnosticStatus.WARN
    d.update()
    d.update()
    assert published()[1:] == [(DiagnosticStatus.OK, "paused"), (DiagnosticStatus.WARN, "paused")]
    if with_summary:
        assert state["built"] == 3  # (only for the three publications)
    time.sleep(0.35)
    d.update()
    assert len(published()) == 4


@pytest.mark.heavy
def test_diagnostics_report_drops_by_reason(make) -> None:  # type: ignore[no-untyped-def]
    """The first drop is published at once, later ones at most once per wall second; keys are
    ``dropped_messages`` and ``dropped: <topic>: <reason>``; the simulator keeps its own keys."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor

    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor

    sensor = make(BoundarySensor)
    sim = small_sim(make, start_paused=True)
    probe = make(lambda **kw: rclpy.create_node("probe", **kw))
    ex = SingleThreadedExecutor(context=sensor.context)
    for n in (sensor, sim, probe):
        ex.add_node(n)
    got: list[tuple[float, str, dict[str, str]]] = []
    probe.create_subscription(
        DiagnosticArray, topics.DIAGNOSTICS,
        lambda m: got.extend((time.monotonic(), s.name, {kv.key: kv.value for kv in s.values}) for s in m.status), qos.STREAM)

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.02)

    end = time.monotonic() + 10
    while time.monotonic() < end and probe.count_publishers(topics.DIAGNOSTICS) < 2:
        ex.spin_once(timeout_sec=0.02)
    spin(0.2)
    got.clear()
    nan_state = RodState(**rod_arrays(5, 0.0, (0, 0, 0)))
    nan_state.x[2] = math.nan
    t0 = time.monotonic()
    sensor.on_rod_state(nan_state)  # the first drop: published at once
    for _ in range(40):
        sensor.on_rod_state(RodState())
    sim.on_couple(CoupleControl(step=0, s=[0.0, 1.0], u=[0.0, 0.0]))
    spin(2.3)
    mine = [(t, v) for t, name, v in got if name == "boundary_sensor" and v["dropped_messages"] != "0"]
    assert mine[0][1] == {"dropped_messages": "1", "dropped: /contgrasp/rod_state: NaN/Inf": "1", "pid": str(os.getpid())}
    assert mine[0][0] - t0 < 0.5
    last = mine[-1][1]
    assert last == {"dropped_messages": "41", "dropped: /contgrasp/rod_state: NaN/Inf": "1",
                    "dropped: /contgrasp/rod_state: too few samples": "40", "pid": str(os.getpid())}
    assert 2 <= len(mine) <= 4  # the first drop, then the 1 s timer (2.3 s spun)
    sim_status = [v for _, name, v in got if name == "rod_simulator"][-1]
    assert {"state", "step", "sim_time_s", "settled", "settle_time_s", "missed_deadlines", "max_penetration", "message",
            "pid"} <= set(sim_status)
    assert sim_status["dropped_messages"] == "1" and sim_status["dropped: /contgrasp/couple: wrong joints"] == "1"
    assert sim_status["state"] == "paused"
    ex.shutdown()


# ---------------------------------------------------------------------------- parameters
def _node_classes() -> dict[str, Any]:
    from contgrasp_ros.nodes.boundary_sensor import BoundarySensor
    from contgrasp_ros.nodes.grasp_controller import GraspController
    from contgrasp_ros.nodes.grasp_quality import GraspQualityNode
    from contgrasp_ros.nodes.rod_simulator import RodSimulator

    return {"sensor": BoundarySensor, "controller": GraspController, "quality": GraspQualityNode, "simulator": RodSimulator}


BAD_AT_RUN_TIME = {
    "sensor": [("contact_tolerance", -1.0, "out of range"), ("contact_tolerance", "x", "type"),
               ("max_future_stamp", math.nan, "out of range"), ("max_future_stamp", 1, "type")],
    "controller": [("mu1", 0.0, "out of range"), ("mu1", "fast", "type"), ("mu2", math.inf, "out of range"),
                   ("adaptive_mu2", "yes", "type"), ("object_radius", -0.1, "out of range"),
                   ("length_unit", 1e-9, "mu2 beyond"), ("n_elements", 50, "read-only"), ("radius_tip", 0.002, "read-only")],
    "quality": [("rate_hz", -1.0, "out of range"), ("reference_x", "a", "type")],
    "simulator": [("timeout_fallback", "explode", "must be one of"), ("timeout_fallback", 3, "type"),
                  ("couple_timeout", 0.0, "out of range"), ("duration", 5.0, "read-only"), ("object", "ellipse", "read-only"),
                  ("lockstep", False, "read-only"), ("start_paused", True, "read-only"), ("max_kinetic_energy", 0.0, "out of range"),
                  ("max_penetration_limit", -1.0, "out of range"), ("marker_period", math.nan, "out of range"),
                  ("clock_period", -0.01, "out of range"), ("clock_period", math.nan, "out of range"),
                  ("sample_period", -0.01, "out of range"), ("sample_period", math.inf, "out of range"),
                  ("sample_period", "often", "type"), ("settle_speed", 1.0, "read-only")],
}


@pytest.mark.parametrize("which", sorted(BAD_AT_RUN_TIME))
def test_invalid_parameters_are_refused_at_run_time(make, which) -> None:  # type: ignore[no-untyped-def]
    node = make(_node_classes()[which], **({"n_elements": 6} if which == "simulator" else {}))
    for name, value, why in BAD_AT_RUN_TIME[which]:
        old = node.get_parameter(name).value
        res = node.set_parameters([Parameter(name, value=value)])[0]
        assert not res.successful, (name, value)
        assert res.reason and (why in res.reason or (why == "type" and "Wrong parameter type" in res.reason)), (name, res.reason)
        assert node.get_parameter(name).value == old
    # valid changes still go through
    ok = {"sensor": ("contact_tolerance", 0.001), "controller": ("mu1", 2.0), "quality": ("rate_hz", 5.0),
          "simulator": ("timeout_fallback", "zero")}[which]
    assert node.set_parameters([Parameter(ok[0], value=ok[1])])[0].successful
    assert node.get_parameter(ok[0]).value == ok[1]


@pytest.mark.parametrize(("which", "params"), [
    ("simulator", {"timeout_fallback": "explode"}),
    ("simulator", {"object": "square"}),
    ("simulator", {"object_center": [0.08]}),
    ("simulator", {"object": "circle:0.5"}),  # (the straight arm starts inside the object: check_start)
    ("simulator", {"object_center": [1.0, 1.0]}),  # (the object out of the arm's reach)
    ("simulator", {"object": "outline"}),
    ("simulator", {"control_period": 0.01, "dt": 0.003}),
    ("simulator", {"max_kinetic_energy": -1.0}),
    ("simulator", {"sample_period": -0.01}),
    ("simulator", {"lockstep": False, "couple_wait": 1.0}),  # (a whole period: the step would not fit)
    ("controller", {"adaptive_mu2": True, "length_unit": 1e-9}),
    ("controller", {"mu1": 0.0}),
    ("controller", {"radius_base": 0.5}),
    ("quality", {"rate_hz": "fast"}),
    ("sensor", {"max_future_stamp": -1.0}),
])
def test_invalid_parameters_are_refused_at_start_up(ros_context, which, params) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_core.errors import ContgraspError

    with pytest.raises((rclpy.exceptions.ParameterException, ContgraspError)):
        _node_classes()[which](context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_a_start_inside_the_object_is_refused_at_start_up(ros_context) -> None:  # type: ignore[no-untyped-def]
    """The simulator refuses an object across its straight start as the core does
    (:func:`contgrasp_core.scenario.check_start`), not by failing the run at t = 0."""
    from contgrasp_core.errors import InvalidParameterError

    with pytest.raises(InvalidParameterError, match="the arm starts inside the object"):
        _node_classes()["simulator"](context=ros_context, parameter_overrides=[
            Parameter("n_elements", value=6), Parameter("object", value="circle:0.02"),
            Parameter("object_center", value=[0.1, 0.0])])


def test_invalid_start_up_parameter_exits_with_code_2() -> None:
    env = dict(os.environ, ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.run([sys.executable, "-m", "contgrasp_ros.nodes.rod_simulator", "--ros-args", "-p", "timeout_fallback:=explode"],
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 2
    assert "timeout_fallback" in proc.stderr and "must be one of" in proc.stderr


# ---------------------------------------------------------------------------- divergence
def _nan_state(sim: Any) -> None:
    from contgrasp_core.rod.integrator import RodState as CoreState

    def advance(_couple: object, _wrench: object = None) -> None:
        st_ = sim.session.state
        sim.session.state = CoreState(t=st_.t + 0.01, theta=st_.theta, omega=np.full_like(st_.omega, np.nan))
        sim.session.k += 1

    sim.session.advance = advance


def _newton_fails(sim: Any) -> None:
    def advance(_couple: object, _wrench: object = None) -> None:
        raise StepFailedError(f"Newton failed to converge at t={sim.session.state.t + 0.004:.6g} s even with dt=1e-05 s")

    sim.session.advance = advance


@pytest.mark.parametrize(("case", "params", "inject", "cause"), [
    ("nan", {}, _nan_state, "NaN/Inf in the rod state"),
    ("energy", {"max_kinetic_energy": 1e-12}, None, "kinetic energy"),
    ("absurd couple", {}, "absurd", None),
    ("newton", {}, _newton_fails, "Newton failed to converge"),
])
def test_divergence_stops_the_simulation(make, case, params, inject, cause) -> None:  # type: ignore[no-untyped-def]
    from rclpy.executors import SingleThreadedExecutor

    from contgrasp_ros.plumbing.convert import couple_to_msg
    from contgrasp_ros.nodes.rod_simulator import _stamp

    sim = small_sim(make, **params)
    status: list[dict[str, str]] = []
    sim.diagnostics.pub = Sink()
    if callable(inject):
        inject(sim)
    u = np.full(6, 1e-6) if inject != "absurd" else np.full(6, 1e4)
    for _ in range(3):
        if sim.failure:
            break
        k = sim.session.k
        sim.on_couple(couple_to_msg(sim.model.joint_s, u, Header(stamp=_stamp(float(sim.session.state.t))), k))
    status = [{kv.key: kv.value for kv in m.status[0].values} for m in sim.diagnostics.pub.msgs]
    assert sim.failure and status[-1]["state"] == "failed"
    msg = status[-1]["message"]
    assert msg.startswith(f"t = {float(sim.session.state.t):.6g} s: ")
    if cause is not None:
        assert cause in msg
    else:  # an absurd couple: whichever guard trips first
        assert any(c in msg for c in ("kinetic energy", "inside the object", "Newton failed", "NaN/Inf")), msg
    k, n_status = sim.session.k, len(sim.diagnostics.pub.msgs)
    # stepping stopped: further couples, ticks and resumes do not advance it
    sim.on_couple(couple_to_msg(sim.model.joint_s, u, Header(stamp=_stamp(float(sim.session.state.t))), k))
    ex = SingleThreadedExecutor(context=sim.context)
    ex.add_node(sim)
    sim.set_parameters([Parameter("couple_timeout", value=0.01)])
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.02)
    ex.shutdown()
    assert sim.session.k == k and sim.failure
    assert all(m.status[0].values[0].value == "failed" for m in sim.diagnostics.pub.msgs[n_status:])
    assert sim.drops.total == 0  # the answers to a failed run are not bad messages


def test_deep_penetration_fails_the_run_at_once(make) -> None:  # type: ignore[no-untyped-def]
    """A first state across the object: the run is already broken at t = 0. (A straight start
    inside the object is refused at start-up, :func:`contgrasp_core.scenario.check_start`: the
    run starts here from a given state, the straight rod turned through the object's centre.)"""
    from contgrasp_core.rod.integrator import RodState as CoreState
    from contgrasp_core.rod.session import LoopSession

    sim = small_sim(make, object="circle:0.02", object_center=[0.1, 0.03], start_paused=True)
    assert not sim.failure
    across = CoreState(t=0.0, theta=np.full(6, np.arctan2(0.03, 0.1)), omega=np.zeros(6))
    sim.session = LoopSession(sim.system, sim.config, across)
    sim._publish_first_observation()
    assert sim.failure.startswith("t = 0 s: simulation diverged: the rod surface is ")
    assert "max_penetration_limit" in sim.failure
    assert sim._status() == "failed" and not sim._can_step()


def test_paper_scale_limits_do_not_trip_a_normal_run(make) -> None:  # type: ignore[no-untyped-def]
    """A short lock-step run with the controller's law: no failure with the default limits."""
    from contgrasp_core.control import paper_gains
    from contgrasp_core.contact import sense
    from contgrasp_core.control import feedback_at_joints
    from contgrasp_ros.plumbing.convert import couple_to_msg
    from contgrasp_ros.nodes.rod_simulator import _stamp

    sim = small_sim(make, n_elements=20, control_period=0.002, damping=1.0)
    gains = paper_gains(sim.model, 0.025)
    for _ in range(60):
        obs = sim.session.observe()
        c = sense(obs.shape, OBJ, obs.radius)
        sim.on_couple(couple_to_msg(sim.model.joint_s, feedback_at_joints(sim.model, gains, c.rho, c.alpha),
                                    Header(stamp=_stamp(obs.t)), obs.k))
    assert not sim.failure and sim.session.k == 60 and sim.drops.total == 0


def test_loop_session_check_divergence() -> None:
    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig
    from contgrasp_core.rod.integrator import RodState as CoreState
    from contgrasp_core.rod.session import DivergenceLimits, LoopSession, SimulationDivergedError

    model = RodModel(n_elements=6)
    session = LoopSession(RodSystem(model, Obstacle(OBJ)), ClosedLoopConfig(duration=1.0, control_period=0.01))
    limits = DivergenceLimits(max_penetration=1e-3, max_kinetic_energy=1.0)
    assert session.check_divergence(limits).k == 0
    session.state = CoreState(t=0.5, theta=session.state.theta, omega=np.full(6, 1e4))
    session._observed = None
    with pytest.raises(SimulationDivergedError, match="kinetic energy"):
        session.check_divergence(limits)
    session.state = CoreState(t=0.5, theta=np.full(6, np.inf), omega=np.zeros(6))
    with pytest.raises(SimulationDivergedError, match="NaN/Inf"):
        session.check_divergence(limits)


def test_guarded_spin_survives_a_message_rclpy_cannot_take(ros_context) -> None:  # type: ignore[no-untyped-def]
    """rclpy can fail inside take_message under load (seen in the soak test at SIGINT): the
    failure is counted and spinning goes on; after shutdown it ends as a normal shutdown; a
    failure that persists is re-raised."""
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node

    from contgrasp_ros.plumbing.faults import DropCounter
    from contgrasp_ros.plumbing.runtime import GuardedSpin

    class FlakyExecutor:
        def __init__(self, fail: int, context_ok: bool = True) -> None:
            self.fail, self.turns = fail, 0
            self.context = type("Ctx", (), {"ok": staticmethod(lambda: context_ok)})()

        def spin_once(self, timeout_sec=None) -> None:  # type: ignore[no-untyped-def]
            self.turns += 1
            if self.turns <= self.fail:
                raise RuntimeError("Unable to convert call argument '0' to Python object")

    node = Node("guarded_spin_test", context=ros_context)
    try:
        drops = DropCounter(node)
        spin = GuardedSpin(FlakyExecutor(fail=2), drops, max_failures=5)  # type: ignore[arg-type]
        for _ in range(4):
            spin(0.0)
        assert drops.counts == {"executor: internal error: RuntimeError": 2} and spin.streak == 0
        with pytest.raises(ExternalShutdownException):
            GuardedSpin(FlakyExecutor(fail=1, context_ok=False), drops)(0.0)  # type: ignore[arg-type]
        persistent = GuardedSpin(FlakyExecutor(fail=100), drops, max_failures=3)  # type: ignore[arg-type]
        for _ in range(3):
            persistent(0.0)
        with pytest.raises(RuntimeError):
            persistent(0.0)
    finally:
        node.destroy_node()


def test_a_callback_failing_because_the_node_is_stopping_is_not_an_internal_error() -> None:
    """SIGINT shuts the context down while a callback publishes: that is the node stopping,
    not a fault; the same failure on a live context is counted (and logged with its traceback)."""
    from rclpy.context import Context

    from contgrasp_ros.plumbing.faults import DropCounter

    ctx = Context()
    rclpy.init(context=ctx, domain_id=fresh_domain_id())
    node = rclpy.create_node("stopping_probe", context=ctx)
    drops = DropCounter(node)

    def publish_fails() -> None:
        raise RuntimeError("Failed to publish: publisher's context is invalid")

    guarded_cb = drops.guard("/contgrasp/couple", publish_fails)
    guarded_cb()
    assert drops.counts == {"/contgrasp/couple: internal error: RuntimeError": 1}
    rclpy.shutdown(context=ctx)
    guarded_cb()
    assert drops.counts == {"/contgrasp/couple: internal error: RuntimeError": 1}
    node.destroy_node()


def kernel_interrupted() -> SystemError:
    """What a compiled kernel raises when a SIGINT is handled while it boxes its result: CPython's
    "returned a result with an exception set" SystemError, caused by the KeyboardInterrupt (seen
    from frames_nodes under SIGINT, also with a second SystemError between them)."""
    try:
        try:
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as ki:
                raise SystemError("CPUDispatcher(<function frames_nodes>) returned a result with an exception set") from ki
        except SystemError as inner:
            raise SystemError("CPUDispatcher(<function frames_nodes>) returned a result with an exception set") from inner
    except SystemError as err:
        return err


@pytest.mark.parametrize("where", ["simulator step", "callback"])
def test_a_ctrl_c_inside_a_compiled_kernel_stops_the_node_and_fails_nothing(make, where) -> None:  # type: ignore[no-untyped-def]
    """Ctrl-C on a stepping simulator once ended its run as failed ("simulation stopped: ...
    SystemError: CPUDispatcher(<function frames_nodes>) returned a result with an exception
    set"): the interrupt surfaces as the KeyboardInterrupt it is, nothing is counted or failed."""
    from contgrasp_ros.plumbing.convert import couple_to_msg
    from contgrasp_ros.nodes.rod_simulator import _stamp

    sim = small_sim(make)

    def interrupted(*args: Any, **kwargs: Any) -> None:
        raise kernel_interrupted()

    if where == "simulator step":
        sim.session.advance = interrupted
    else:
        sim._advance = interrupted
    with pytest.raises(KeyboardInterrupt):
        sim.on_couple(couple_to_msg(sim.model.joint_s, np.zeros(6), Header(stamp=_stamp(0.0)), 0))
    assert not sim.failure and sim.drops.total == 0 and sim.session.k == 0
