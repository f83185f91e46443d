"""Random and malformed messages: a conversion either returns the message's arrays unchanged
(validated) or raises MessageError with the documented reason, never anything else (the nodes
catch MessageError, count the drop under its reason and keep running).

Each property draws a valid message, the same message with one known defect, or fields drawn
with no structure at all. A valid message must be accepted and round-trip exactly; a defective
one must raise MessageError with the reason convert.py documents for that defect; an
unstructured one must do either (accepted: round-trips; rejected: MessageError). Every test
counts both outcomes over its examples and fails unless both occurred, so a generator that
only ever produces rejected (or accepted) messages cannot pass silently.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("contgrasp_msgs.msg")

from contgrasp_msgs.msg import ContactState, CoupleControl, ObjectBoundary, RodState  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from contgrasp_core.boundary import circle, deformed_circle, ellipse  # noqa: E402
from contgrasp_core.rod.session import FeedbackExpansion  # noqa: E402
from contgrasp_ros.plumbing.convert import (  # noqa: E402
    MAX_ABS,
    MessageError,
    boundary_from_msg,
    boundary_to_msg,
    contact_arrays,
    couple_arrays,
    HeldShape,
    rod_state_arrays,
)

values = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.floats(-1.0, 1.0))
arrays = st.lists(values, max_size=8)
finite = st.floats(-10.0, 10.0, allow_nan=False)
steps = st.lists(st.floats(1e-3, 1.0), min_size=1, max_size=8)

ACCEPTED, REJECTED = "accepted", "rejected"
Case = tuple[dict[str, Any], str | None, bool]  # (message fields, expected reason or None, structured)


def counting(prop: Callable[[Counter[str]], Callable[[], None]]) -> Callable[[], None]:
    """Run the hypothesis property ``prop(outcomes)`` and then require that both outcomes occurred."""

    def test() -> None:
        outcomes: Counter[str] = Counter()
        prop(outcomes)()
        assert outcomes[ACCEPTED] > 0 and outcomes[REJECTED] > 0, f"only one outcome was exercised: {dict(outcomes)}"

    test.__name__ = prop.__name__
    test.__doc__ = prop.__doc__
    return test


def convert(fn: Callable[[Any], Any], msg: Any, expected: str | None, structured: bool, outcomes: Counter[str]) -> Any:
    """``fn(msg)``; checks the outcome against ``expected`` (None: must be accepted) for a
    structured case; returns the result, or None when it was rejected as it should be."""
    try:
        out = fn(msg)
    except MessageError as exc:
        outcomes[REJECTED] += 1
        if structured:
            assert expected is not None, f"a valid message was rejected: {exc} (reason {exc.reason!r})"
            assert exc.reason == expected or (expected.endswith(": *") and exc.reason.startswith(expected[:-1])), (
                f"rejected with reason {exc.reason!r}, documented: {expected!r} ({exc})"
            )
        return None
    outcomes[ACCEPTED] += 1
    assert not (structured and expected is not None), f"a message with a defect ({expected}) was accepted"
    return out


def _equal(a: Any, b: Any) -> bool:
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float))


@st.composite
def _defect(draw: st.DrawFn, fields: dict[str, list[Any]], cols: tuple[str, ...], *, max_abs: bool = True,
            grid: bool = True) -> str | None:
    """Apply none or one known defect to the equally long columns ``cols`` of ``fields`` (first
    column: the arclength s); return the reason _arrays documents for it."""
    kinds = ["none", "too few", "length", "nan", "inf"] + (["range"] if max_abs else []) + (["grid"] if grid else [])
    kind = draw(st.sampled_from(kinds))
    n = len(fields[cols[0]])
    if kind == "none":
        return None
    if kind == "too few":
        for c in cols:
            fields[c] = fields[c][:1]
        return "too few samples"
    col = draw(st.sampled_from(cols))
    i = draw(st.integers(0, n - 1))
    if kind == "length":
        other = draw(st.sampled_from(cols[1:]))  # one column shorter or longer than s
        fields[other] = fields[other][:-1] if draw(st.booleans()) else fields[other] + [0.0]
        return "length mismatch"
    if kind in ("nan", "inf"):
        fields[col][i] = math.nan if kind == "nan" else draw(st.sampled_from([math.inf, -math.inf]))
        return "NaN/Inf"
    if kind == "range":
        col = draw(st.sampled_from(cols[1:]))
        fields[col][i] = draw(st.sampled_from([1.0, -1.0])) * draw(st.floats(2.0 * MAX_ABS, 1e300))
        return "out of range"
    j = draw(st.integers(1, n - 1))
    fields[cols[0]][j] = fields[cols[0]][j - 1]  # a repeated arclength
    return "bad arclength grid"


# ------------------------------------------------------------------------------------- RodState
ROD = ("s", "x", "y", "theta", "radius")


@st.composite
def rod_cases(draw: st.DrawFn) -> Case:
    if draw(st.integers(0, 4)) == 0:
        return {k: draw(arrays) for k in (*ROD, "kappa")}, None, False
    s = np.cumsum(draw(st.lists(st.floats(1e-3, 1.0), min_size=2, max_size=8))).tolist()
    n = len(s)
    f: dict[str, Any] = {"s": s}
    for k in ("x", "y", "theta"):
        f[k] = draw(st.lists(finite, min_size=n, max_size=n))
    f["radius"] = draw(st.lists(st.floats(0.0, 0.05), min_size=n, max_size=n))
    f["kappa"] = draw(st.sampled_from([[], [0.5] * n]))
    reason = draw(_defect(f, ROD))
    if reason is None:
        extra = draw(st.sampled_from(["none", "radius", "kappa length", "kappa nan"]))
        if extra == "radius":
            f["radius"][draw(st.integers(0, n - 1))] = -draw(st.floats(1e-9, 1.0))
            reason = "out of range"
        elif extra == "kappa length":
            f["kappa"] = [0.5] * (n + 1)
            reason = "length mismatch"
        elif extra == "kappa nan":
            f["kappa"] = [0.5] * (n - 1) + [math.nan]
            reason = "NaN/Inf"
    return f, reason, True


@counting
def test_rod_state(outcomes: Counter[str]) -> Callable[[], None]:
    """RodState: accepted arrays equal the message's; each defect has its documented reason."""

    @settings(max_examples=200, deadline=None)
    @given(case=rod_cases(), step=st.integers(0, 2**40))
    def prop(case: Case, step: int) -> None:
        f, reason, structured = case
        msg = RodState(step=step, **f)
        out = convert(rod_state_arrays, msg, reason, structured, outcomes)
        if out is None:
            return
        assert out.step == step
        for k in (*ROD, "kappa"):
            assert _equal(getattr(out, k), f[k]), k
        assert len(out.s) >= 2 and np.all(np.diff(out.s) > 0)

    return prop


# ---------------------------------------------------------------------------------- ContactState
CONTACT = ("s", "rho", "alpha", "delta", "s_o", "shadow_x", "shadow_y")


@st.composite
def contact_cases(draw: st.DrawFn) -> Case:
    if draw(st.integers(0, 4)) == 0:
        cols = dict(zip(CONTACT, draw(st.lists(arrays, min_size=7, max_size=7)), strict=True))
        return {**cols, "in_contact": draw(st.lists(st.booleans(), max_size=8)), "contact_tolerance": draw(values)}, None, False
    s = np.cumsum(draw(steps)).tolist() + [100.0]
    n = len(s)
    f: dict[str, Any] = {"s": s, **{k: draw(st.lists(finite, min_size=n, max_size=n)) for k in CONTACT[1:]}}
    f["in_contact"] = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    f["contact_tolerance"] = draw(st.floats(0.0, 1e-2))
    reason = draw(_defect(f, CONTACT))
    if reason is None:
        extra = draw(st.sampled_from(["none", "flags", "tol"]))
        if extra == "flags":
            f["in_contact"] = f["in_contact"] + [True]
            reason = "length mismatch"
        elif extra == "tol":
            f["contact_tolerance"] = draw(st.sampled_from([-1e-3, math.nan, math.inf, 2.0 * MAX_ABS]))
            reason = "out of range"
    return f, reason, True


@counting
def test_contact_state(outcomes: Counter[str]) -> Callable[[], None]:
    """ContactState: accepted arrays (shadow = (shadow_x, shadow_y)) equal the message's."""

    @settings(max_examples=200, deadline=None)
    @given(case=contact_cases())
    def prop(case: Case) -> None:
        f, reason, structured = case
        out = convert(contact_arrays, ContactState(**f), reason, structured, outcomes)
        if out is None:
            return
        for k in CONTACT[:5]:
            assert _equal(getattr(out, k), f[k]), k
        assert _equal(out.shadow[:, 0], f["shadow_x"]) and _equal(out.shadow[:, 1], f["shadow_y"])
        assert out.in_contact.dtype == np.bool_ and out.in_contact.tolist() == list(f["in_contact"])
        assert out.tol == f["contact_tolerance"] and np.isfinite(out.tol) and out.tol >= 0

    return prop


# --------------------------------------------------------------------------------- CoupleControl
COUPLE = ("s", "u")
EXPANSION = ("rho_ref", "alpha_ref", "du_drho", "du_dalpha")


@st.composite
def couple_cases(draw: st.DrawFn) -> Case:
    if draw(st.integers(0, 4)) == 0:
        return dict(zip((*COUPLE, *EXPANSION), draw(st.lists(arrays, min_size=6, max_size=6)), strict=True)), None, False
    s = np.cumsum(draw(steps)).tolist() + [100.0]
    n = len(s)
    # only finiteness is required of the couple and the gains: huge finite values are accepted
    big = st.floats(-1e300, 1e300, allow_nan=False)
    f: dict[str, Any] = {"s": s, "u": draw(st.lists(big, min_size=n, max_size=n))}
    kind = draw(st.sampled_from(["plain", "expansion", "hold"]))
    cols = {"plain": COUPLE, "expansion": (*COUPLE, *EXPANSION), "hold": (*COUPLE, "kappa_ref")}[kind]
    for k in EXPANSION:
        f[k] = draw(st.lists(big, min_size=n, max_size=n)) if kind == "expansion" else []
    if kind == "hold":  # the holding law's hold: a rest curvature and a gain >= 0
        f["kappa_ref"] = draw(st.lists(big, min_size=n, max_size=n))
        f["hold_gain"] = draw(st.floats(0.0, 1e6))
    f["transition"] = draw(st.booleans())
    reason = draw(_defect(f, cols, max_abs=False))
    if reason is None and kind == "expansion" and draw(st.booleans()):
        f[draw(st.sampled_from(EXPANSION))] = []  # a partial expansion
        reason = "length mismatch"
    elif reason is None and kind == "hold" and draw(st.booleans()):
        if draw(st.booleans()):
            f["hold_gain"] = draw(st.sampled_from([-1.0, math.nan, math.inf]))
            reason = "out of range"
        else:  # a hold with an expansion: which would the simulator apply?
            f[draw(st.sampled_from(EXPANSION))] = [0.0] * n
            reason = "hold and expansion"
    return f, reason, True


@counting
def test_couple(outcomes: Counter[str]) -> Callable[[], None]:
    """CoupleControl: accepted -> (step, s, u) or the FeedbackExpansion or the hold (HeldShape),
    equal to the message's, and its transition flag."""

    @settings(max_examples=200, deadline=None)
    @given(case=couple_cases(), step=st.integers(0, 2**40))
    def prop(case: Case, step: int) -> None:
        f, reason, structured = case
        out = convert(couple_arrays, CoupleControl(step=step, **f), reason, structured, outcomes)
        if out is None:
            return
        k, s, couple, transition = out
        assert k == step and _equal(s, f["s"]) and transition == f.get("transition", False)
        assert s.flags.writeable  # (numba compiles read-only arrays separately: the simulator's kernels see these)
        if len(f.get("kappa_ref", [])):
            assert isinstance(couple, HeldShape) and couple.gain == f["hold_gain"]
            assert _equal(couple.u, f["u"]) and _equal(couple.kappa_ref, f["kappa_ref"])
        elif any(len(f[e]) for e in EXPANSION):
            assert isinstance(couple, FeedbackExpansion)
            assert _equal(couple.u, f["u"])
            for field, name in (("rho_ref", "rho_ref"), ("alpha_ref", "alpha_ref"), ("g_rho", "du_drho"), ("g_alpha", "du_dalpha")):
                assert _equal(getattr(couple, field), f[name]), name
        else:
            assert not isinstance(couple, (FeedbackExpansion, HeldShape)) and _equal(couple, f["u"])

    return prop


# -------------------------------------------------------------------------------- ObjectBoundary
analytic = st.one_of(
    st.builds(circle, st.floats(0.01, 5.0), st.tuples(finite, finite)),
    st.builds(ellipse, st.floats(0.01, 5.0), st.floats(0.01, 5.0), st.tuples(finite, finite), st.floats(-3.0, 3.0)),
    st.builds(deformed_circle, st.floats(0.01, 5.0), st.floats(0.0, 0.2), st.integers(2, 5), st.floats(-3.0, 3.0),
              st.tuples(finite, finite)),
)


@st.composite
def object_cases(draw: st.DrawFn) -> tuple[dict[str, Any], str | None, bool, Any]:
    """(message fields, expected reason, structured, the boundary a valid message describes)."""
    if draw(st.integers(0, 4)) == 0:
        names = draw(st.lists(st.sampled_from(["R", "a", "b", "center_x", "center_y", "angle", "amplitude", "lobes", "phase"]),
                              max_size=9))
        vals = draw(st.lists(values, min_size=9, max_size=9))
        pts = draw(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), max_size=12))
        kind = draw(st.sampled_from(["circle", "ellipse", "deformed_circle", "points", "nonsense"]))
        f = {"kind": kind, "parameter_names": names, "parameter_values": vals[: len(names)],
             "x": [p[0] for p in pts], "y": [p[1] for p in pts]}
        return f, None, False, None
    b = draw(analytic)
    msg = boundary_to_msg(b, Header(), samples=draw(st.integers(48, 96)))
    f = {"kind": msg.kind, "parameter_names": list(msg.parameter_names), "parameter_values": list(msg.parameter_values),
         "x": list(msg.x), "y": list(msg.y)}
    spacing = b.length / len(f["x"])
    resolved = float(np.max(np.abs(b.curvature(np.linspace(0.0, b.length, 2048, endpoint=False))))) * spacing < 0.5
    if resolved and draw(st.booleans()):
        # rebuilt from the samples as a closed spline: only where the samples resolve the curve (a
        # 64:1 ellipse sampled 49 times has its ends between two samples, and the interpolating
        # spline through them rightly crosses itself)
        f["kind"] = "points"
    defect = draw(st.sampled_from(["none", "names", "range", "missing", "invalid", "xy", "crossing", "far points"]))
    analytic_kind = f["kind"] != "points"
    if defect == "names":
        f["parameter_names"] = f["parameter_names"][:-1]
        return f, "length mismatch", True, None
    if defect == "range":
        f["parameter_values"][0] = 2.0 * MAX_ABS
        return f, "out of range", True, None
    if defect == "missing" and analytic_kind:
        i = draw(st.integers(0, len(f["parameter_names"]) - 1))
        del f["parameter_names"][i], f["parameter_values"][i]
        return f, "bad object: missing parameters", True, None
    if defect == "invalid" and analytic_kind:
        f["parameter_values"][0] = draw(st.sampled_from([0.0, -1.0, math.nan]))  # R or a: must be > 0
        return f, "bad object: *", True, None
    if defect == "xy" and not analytic_kind:
        f["y"] = f["y"][:-1]
        return f, "length mismatch", True, None
    if defect == "crossing" and not analytic_kind:
        f["x"], f["y"] = [0.0, 1.0, 1.0, 0.0, 0.5], [0.0, 1.0, 0.0, 1.0, 1.5]  # a bow tie
        return f, "bad object: SelfIntersectionError", True, None
    if defect == "far points" and not analytic_kind:
        f["x"][0] = 2.0 * MAX_ABS
        return f, "out of range", True, None
    return f, None, True, b


@pytest.mark.heavy
@counting
def test_object_boundary(outcomes: Counter[str]) -> Callable[[], None]:
    """ObjectBoundary: an analytic kind rebuilds the very boundary boundary_to_msg described
    (kind, parameters, length); "points" rebuilds a closed spline through the samples."""

    @settings(max_examples=80, deadline=None)
    @given(case=object_cases())
    def prop(case: tuple[dict[str, Any], str | None, bool, Any]) -> None:
        f, reason, structured, original = case
        msg = ObjectBoundary(**f)
        b = convert(boundary_from_msg, msg, reason, structured, outcomes)
        if b is None:
            return
        assert np.isfinite(b.length) and b.length > 0
        if original is None:
            return
        if f["kind"] == "points":
            assert b.kind == "points" and b.params["n_points"] == len(f["x"])
            pts = np.stack([f["x"], f["y"]], -1)
            _, curve = b.sample(8192)
            gap = np.min(np.hypot(*(pts[:, None, :] - curve[None, :, :]).transpose(2, 0, 1)), axis=1)
            assert np.max(gap) <= 1e-3 * original.length, "the spline does not pass near the samples"
            assert b.length == pytest.approx(original.length, rel=0.02)
        else:
            assert b.kind == original.kind and b.params == original.params
            assert b.length == pytest.approx(original.length, rel=1e-12)

    return prop
