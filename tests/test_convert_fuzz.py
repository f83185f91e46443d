"""Random malformed messages: conversions either return validated arrays or raise MessageError,
never anything else (the nodes catch MessageError, count the drop and keep running)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("contgrasp_msgs.msg")

from contgrasp_msgs.msg import ContactState, CoupleControl, ObjectBoundary, RodState  # noqa: E402
from contgrasp_ros.convert import (  # noqa: E402
    MessageError,
    boundary_from_msg,
    contact_arrays,
    couple_arrays,
    rod_state_arrays,
)

values = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.floats(-1.0, 1.0))
arrays = st.lists(values, max_size=8)


@settings(max_examples=150, deadline=None)
@given(s=arrays, x=arrays, y=arrays, theta=arrays, radius=arrays, kappa=arrays)
def test_rod_state(s, x, y, theta, radius, kappa) -> None:  # type: ignore[no-untyped-def]
    msg = RodState(s=s, x=x, y=y, theta=theta, radius=radius, kappa=kappa)
    try:
        out = rod_state_arrays(msg)
    except MessageError:
        return
    assert len(out.s) >= 2 and np.all(np.diff(out.s) > 0)
    for a in (out.s, out.x, out.y, out.theta, out.radius):
        assert a.shape == out.s.shape and np.all(np.isfinite(a))


@settings(max_examples=150, deadline=None)
@given(cols=st.lists(arrays, min_size=7, max_size=7), flags=st.lists(st.booleans(), max_size=8), tol=values)
def test_contact_state(cols, flags, tol) -> None:  # type: ignore[no-untyped-def]
    names = ("s", "rho", "alpha", "delta", "s_o", "shadow_x", "shadow_y")
    msg = ContactState(in_contact=flags, contact_tolerance=tol, **dict(zip(names, cols, strict=True)))
    try:
        out = contact_arrays(msg)
    except MessageError:
        return
    assert np.isfinite(out.tol) and out.tol >= 0 and out.in_contact.shape == out.s.shape


@settings(max_examples=150, deadline=None)
@given(cols=st.lists(arrays, min_size=6, max_size=6))
def test_couple(cols) -> None:  # type: ignore[no-untyped-def]
    names = ("s", "u", "rho_ref", "alpha_ref", "du_drho", "du_dalpha")
    msg = CoupleControl(**dict(zip(names, cols, strict=True)))
    try:
        couple_arrays(msg)
    except MessageError:
        return


@settings(max_examples=60, deadline=None)
@given(
    kind=st.sampled_from(["circle", "ellipse", "deformed_circle", "points", "nonsense"]),
    names=st.lists(st.sampled_from(["R", "a", "b", "center_x", "center_y", "angle", "amplitude", "lobes", "phase"]), max_size=9),
    vals=st.lists(values, min_size=9, max_size=9),
    pts=st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), max_size=12),
)
def test_object_boundary(kind, names, vals, pts) -> None:  # type: ignore[no-untyped-def]
    msg = ObjectBoundary(kind=kind, parameter_names=names, parameter_values=vals[: len(names)],
                         x=[p[0] for p in pts], y=[p[1] for p in pts])
    try:
        b = boundary_from_msg(msg)
    except MessageError:
        return
    assert np.isfinite(b.length) and b.length > 0
