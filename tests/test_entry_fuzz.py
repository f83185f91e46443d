"""Property-based fuzz tests of every public library and CLI entry point (docs/RELIABILITY.md).

Library: called with random inputs, valid ones mixed with NaN, +-Inf, bad sizes, huge values,
wrong shapes, empty arrays and wrong Python types, an entry point returns finite results or raises
a :class:`~contgrasp_core.errors.ContgraspError` subclass with a message; any other exception, or
a RuntimeWarning or UserWarning, fails. Not fuzzed: user callables (trusted), results non-finite by
definition (flagged invalid), a non-converged optimal grasp (a result), and
:func:`contgrasp_ros.recordings.analysis.analyze`'s overrides
(:func:`test_analyze_overrides_of_the_wrong_type`). CLI: ``contgrasp_core.cli.main(argv)`` with at
least one bad option value returns 2 with exactly one ``contgrasp COMMAND: error: ...`` line on
stderr, caught before any long computation.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import uuid
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from contgrasp_core import arm as A
from contgrasp_core import boundary as B
from contgrasp_core import contact as C
from contgrasp_core.control import law as F
from contgrasp_core import optimal as O
from contgrasp_core import quality as Q
from contgrasp_core import quality_map as S
from contgrasp_core.errors import ContgraspError

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "bags" / "paper_grasp.mcap"
NAN, INF = float("nan"), float("inf")

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
QUICK = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# ----------------------------------------------------------------------------- strategies
BAD_SCALARS = [NAN, INF, -INF, 0.0, -1.0, 1e300, -1e300, 5e-324, "x", "", None, [1.0, 2.0], [], np.array([]),
               np.array([1.0, 2.0]), {}, (), object(), True]
bad = st.sampled_from(BAD_SCALARS)


def num(lo: float = -10.0, hi: float = 10.0) -> st.SearchStrategy[Any]:
    """A valid float in [lo, hi] or (about a third of the time) a bad value."""
    return st.one_of(st.floats(lo, hi, allow_nan=False), st.floats(lo, hi, allow_nan=False), bad)


def wild_floats() -> st.SearchStrategy[float]:
    return st.one_of(st.floats(-10, 10), st.sampled_from([NAN, INF, -INF, 1e300, -1e300, 0.0, 5e-324]))


def vector(min_size: int = 0, max_size: int = 8) -> st.SearchStrategy[Any]:
    """A float array (random values, some non-finite or huge), or something that is not one."""
    good = st.lists(st.floats(-5, 5), min_size=min_size, max_size=max_size).map(np.array)
    wild = st.lists(wild_floats(), min_size=min_size, max_size=max_size).map(np.array)
    return st.one_of(good, good, wild, bad, st.just([[1.0, 2.0], [3.0]]), st.just(["a", "b"]),
                     st.lists(st.floats(-5, 5), min_size=1, max_size=4).map(lambda v: np.array(v)[:, None]))


def grid(max_size: int = 8) -> st.SearchStrategy[Any]:
    """An increasing grid, sometimes broken (unsorted, repeated, non-finite, wrong type)."""
    inc = st.lists(st.floats(0.01, 3.0), min_size=1, max_size=max_size - 1).map(lambda h: np.concatenate([[0.0], np.cumsum(h)]))
    return st.one_of(inc, inc, inc, vector(0, max_size))


def points2(max_size: int = 6) -> st.SearchStrategy[Any]:
    pts = st.lists(st.tuples(wild_floats(), wild_floats()), min_size=0, max_size=max_size).map(
        lambda p: np.array(p, dtype=float).reshape(-1, 2))
    near = st.lists(st.tuples(st.floats(-12, 12), st.floats(-12, 12)), min_size=1, max_size=max_size).map(np.array)
    return st.one_of(near, near, pts, vector())


# ----------------------------------------------------------------------------- the property
def _finite_values(obj: Any) -> Iterable[float]:
    if isinstance(obj, bool | str | None | np.bool_) or callable(obj) and not isinstance(obj, np.ndarray):
        return
    if isinstance(obj, int | float | np.number):
        yield float(obj)
    elif isinstance(obj, np.ndarray):
        if obj.dtype.kind in "fiuc":
            yield from obj.ravel().astype(float)
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _finite_values(v)
    elif isinstance(obj, list | tuple):
        for v in obj:
            yield from _finite_values(v)


def call(fn: Callable[..., Any], *args: Any, finite: Callable[[Any], Any] | None = None, **kwargs: Any) -> Any:
    """Run ``fn``; it must raise a ContgraspError (with a message) or return a result whose
    selected values (``finite(result)``, default the result itself) are all finite.
    RuntimeWarnings and UserWarnings are errors. Returns the result or None after an error."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        warnings.simplefilter("error", UserWarning)
        try:
            out = fn(*args, **kwargs)
        except ContgraspError as exc:
            assert str(exc).strip(), f"{type(exc).__name__} without a message"
            return None
    values = list(_finite_values(out if finite is None else finite(out)))
    assert all(math.isfinite(v) for v in values), f"{getattr(fn, '__name__', fn)} returned non-finite values"
    return out


CIRCLE = B.circle(5.0)
DEFORMED = B.deformed_circle(5.0)
ELLIPSE = B.ellipse(8.0, 4.0, (1.0, -2.0), 0.3)
boundaries = st.sampled_from([CIRCLE, DEFORMED, ELLIPSE])
any_boundary = st.one_of(boundaries, boundaries, boundaries, bad)


def boundary_values(b: B.Boundary) -> list[Any]:
    return [b.length, b.point(np.array([0.0, 0.3 * b.length])), b.curvature(0.5 * b.length)]


# ----------------------------------------------------------------------------- boundary
@QUICK
@given(kind=st.sampled_from(["circle", "ellipse", "fourier", "deformed"]), a=num(0.0, 20.0), b=num(0.0, 20.0),
       center=st.one_of(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), vector(0, 3)), angle=num(),
       coeffs=st.one_of(st.lists(st.floats(-0.3, 0.3), max_size=4), vector(0, 4), st.just(np.zeros(1000))),
       lobes=st.one_of(st.integers(-2, 8), st.just(10**12), bad))
def test_boundary_constructors(kind, a, b, center, angle, coeffs, lobes) -> None:  # type: ignore[no-untyped-def]
    if kind == "circle":
        out = call(B.circle, a, center, finite=boundary_values)
    elif kind == "ellipse":
        out = call(B.ellipse, a, b, center, angle, finite=boundary_values)
    elif kind == "fourier":
        out = call(B.fourier_polar, a, coeffs, coeffs[::-1] if isinstance(coeffs, list) else coeffs, center, finite=boundary_values)
    else:
        out = call(B.deformed_circle, a, b if not isinstance(b, float) else b / 40.0, lobes, angle, center,
                   finite=boundary_values)
    assert out is None or isinstance(out, B.Boundary)


def _star(radii: list[float], closed: bool) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, len(radii), endpoint=False)
    p = np.c_[np.asarray(radii) * np.cos(t), np.asarray(radii) * np.sin(t)]
    return p if closed else np.vstack([p, p[:1]])


outlines = st.one_of(
    # star-shaped polygons (valid, or clockwise, or with repeated points)
    st.builds(_star, st.lists(st.floats(0.5, 3.0), min_size=5, max_size=30), st.booleans()),
    st.builds(lambda p: p[::-1], st.builds(_star, st.lists(st.floats(0.5, 3.0), min_size=5, max_size=20), st.booleans())),
    # random point clouds: open, self-intersecting, degenerate, too few points
    st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), max_size=12).map(lambda p: np.array(p).reshape(-1, 2)),
    st.lists(st.tuples(wild_floats(), wild_floats()), max_size=8).map(lambda p: np.array(p).reshape(-1, 2)),
    st.just(np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 2], [0, 0]], dtype=float)),  # bow tie
    st.just(np.zeros((7, 2))),
    st.just(np.c_[np.arange(8.0), np.zeros(8)]),  # zero area
    vector(),
)


@pytest.mark.heavy
@FAST
@given(points=outlines, closed=st.booleans(), smoothing=st.one_of(st.just(0.0), num(0.0, 1e-3), st.just(1e-320)))
def test_from_points(points, closed, smoothing) -> None:  # type: ignore[no-untyped-def]
    call(B.from_points, points, closed=closed, smoothing=smoothing, finite=boundary_values)


@QUICK
@given(b=boundaries, s_o=st.one_of(num(-100.0, 100.0), vector(), st.just(1e20)), pts=points2(),
       n=st.one_of(st.integers(-3, 600), st.just(10**12), bad), candidates=st.one_of(st.integers(-2, 6), bad))
def test_boundary_methods(b, s_o, pts, n, candidates) -> None:  # type: ignore[no-untyped-def]
    for method in (b.point, b.tangent_angle, b.tangent, b.normal, b.curvature, b.curvature_derivative,
                   b.curvature_with_derivative):
        call(method, s_o)
    call(b.sample, n)
    call(b.project, pts, candidates=candidates, finite=lambda p: [p.foot, p.s_o, p.distance, p.phi, p.kappa_o])


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Bad input files shared by the tests (and a copy of the shipped recording)."""
    d = tmp_path_factory.mktemp("fuzz")
    out = {
        "missing": d / "missing.csv",
        "dir": d / "a_dir",
        "empty": d / "empty.csv",
        "binary": d / "binary.csv",
        "garbage": d / "garbage.csv",
        "comment": d / "comment.csv",
        "header_only": d / "header.csv",
        "open": d / "open.csv",
        "bowtie": d / "bowtie.csv",
        "nan": d / "nan.csv",
        "one_column": d / "one.csv",
        "under_file": d / "binary.csv" / "x.png",
    }
    out["dir"].mkdir()
    out["empty"].write_text("")
    out["binary"].write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe\xfd garbage")
    out["garbage"].write_text("x,y\n1,2\nfoo,bar\n")
    out["comment"].write_text("# only a comment\n")
    out["header_only"].write_text("s,kappa\n")
    th = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    out["open"].write_text("\n".join(f"{np.cos(t)},{np.sin(t)}" for t in th))
    out["bowtie"].write_text("0,0\n1,0\n0,1\n1,1\n0.5,2\n0,0\n")
    out["nan"].write_text("0,nan\n1,2\n3,inf\n")
    out["one_column"].write_text("1\n2\n3\n")
    if BAG.is_file():
        data = BAG.read_bytes()
        out["bag"] = d / "good.mcap"
        out["bag"].write_bytes(data)
        out["cut"] = d / "cut.mcap"
        out["cut"].write_bytes(data[: len(data) // 3])
        flipped = bytearray(data)
        flipped[len(data) // 2] ^= 0xFF
        out["flip"] = d / "flip.mcap"
        out["flip"].write_bytes(bytes(flipped))
        folder = d / "bad_meta"
        folder.mkdir()
        (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {relative_file_paths: [nope.mcap], storage_identifier: mcap}\n")
        out["bad_meta"] = folder
        folder = d / "garbage_meta"
        folder.mkdir()
        (folder / "metadata.yaml").write_text(": : [\n")
        out["garbage_meta"] = folder
    out["tmp"] = d
    return out


BAD_FILES = ["missing", "dir", "empty", "binary", "garbage", "comment", "header_only", "open", "bowtie", "nan",
             "one_column"]


@FAST
@given(name=st.sampled_from(BAD_FILES), other=st.sampled_from([None, 5, 0, b"x", ["a"], Path("/nonexistent/x")]))
def test_load_points(files, name, other) -> None:  # type: ignore[no-untyped-def]
    pts = call(B.load_points, str(files[name]))
    if pts is not None:
        call(B.from_points, pts)
    call(B.load_points, other)


# ----------------------------------------------------------------------------- arm
@QUICK
@given(x=num(), y=num(), th=num(), length=num(0.0, 30.0), rb=num(0.0, 2.0), rt=st.one_of(st.none(), num(0.0, 2.0)),
       s=st.one_of(grid(), num()), nodes=st.one_of(st.integers(-3, 50), st.just(10**12), bad), kappa=vector(0, 8),
       base=st.one_of(st.just(A.BasePose()), bad))
def test_arm(x, y, th, length, rb, rt, s, nodes, kappa, base) -> None:  # type: ignore[no-untyped-def]
    call(A.BasePose, x, y, th, finite=lambda p: [p.x, p.y, p.theta])
    arm = call(A.Arm, length, rb, rt, finite=lambda a: [a.length, a.radius_base])
    call(A.Arm.paper_tapered, length, finite=lambda a: [a.length, a.radius_base, a.radius_tip])
    if arm is not None:
        call(arm.radius, s)
        call(arm.grid, nodes)
    call(A.arclength_grid, length, nodes)
    call(A.curvature_spline, s, kappa, finite=lambda sp: sp.c)
    call(A.shape_from_curvature, s, kappa, base, finite=lambda sh: [sh.r, sh.theta])


# ----------------------------------------------------------------------------- contact
state = dict(rho=num(0.0, 4.0), alpha=num(0.0, 3.2), s_o=num(-40.0, 40.0))


@QUICK
@given(b=any_boundary, **state, x=num(-15, 15), y=num(-15, 15), th=num())
def test_contact_states(b, rho, alpha, s_o, x, y, th) -> None:  # type: ignore[no-untyped-def]
    call(C.check_state, b, rho, alpha, s_o)
    call(C.base_pose, b, rho, alpha, s_o, finite=lambda p: [p.x, p.y, p.theta])
    try:
        base = A.BasePose(x, y, th)
    except ContgraspError:
        base = x  # a wrong type for initial_state
    call(C.initial_state, b, base)


@FAST
@given(b=any_boundary, s=grid(12), kappa=st.one_of(vector(0, 12), st.just(1e300), st.just(1e12)), **state,
       rtol=st.one_of(st.just(1e-8), num(0.0, 1e-3)), atol=st.one_of(st.just(1e-10), num(0.0, 1e-3)))
def test_integrate_contact(b, s, kappa, rho, alpha, s_o, rtol, atol) -> None:  # type: ignore[no-untyped-def]
    if isinstance(kappa, float) and isinstance(s, np.ndarray):
        kappa = np.full(s.shape, kappa)
    call(C.integrate_contact, s, kappa, b, rho, alpha, s_o, rtol=rtol, atol=atol,
         finite=lambda k: [k.rho, k.alpha, k.s_o])


@QUICK
@given(b=any_boundary, s=grid(10), r=points2(10), theta=vector(0, 10), radius=st.one_of(num(0.0, 1.0), vector(0, 10)),
       tol=num(0.0, 1.0), rho=vector(0, 10), alpha=vector(0, 10), so=vector(0, 10), distance=num(0.0, 5.0),
       s_o0=num(-40.0, 40.0), use_shape=st.booleans())
def test_sensing_and_shapes(b, s, r, theta, radius, tol, rho, alpha, so, distance, s_o0, use_shape) -> None:  # type: ignore[no-untyped-def]
    shape = A.ArmShape(s=s, r=r, theta=theta) if use_shape else theta
    call(C.sense, shape, b, radius, tol=tol, finite=lambda c: [c.rho, c.alpha, c.delta, c.s_o, c.foot, c.kappa_o, c.normal_out])
    call(C.shape_from_contact, s, rho, alpha, so, b, finite=lambda sh: [sh.r, sh.theta])
    call(C.offset_curvature, b, s, distance, s_o0)


# ----------------------------------------------------------------------------- quality
@QUICK
@given(gamma=points2(8), phi=vector(0, 8), ref=st.one_of(st.just((0.0, 0.0)), vector(0, 3)), s=grid(8),
       delta=vector(0, 8), tol=st.one_of(num(0.0, 1.0), vector(0, 8)),
       gmap=st.one_of(vector(0, 6), st.lists(st.lists(wild_floats(), min_size=3, max_size=3), max_size=4).map(np.array)),
       W=st.one_of(vector(0, 9).map(lambda v: v.reshape(3, 3) if isinstance(v, np.ndarray) and v.size == 9 else v),
                   st.just(np.full((3, 3), 1e300)), st.just(np.zeros((0, 0)))),
       length=num(0.0, 10.0))
def test_quality(gamma, phi, ref, s, delta, tol, gmap, W, length) -> None:  # type: ignore[no-untyped-def]
    call(Q.point_grasp_maps, gamma, phi, ref)
    call(Q.discrete_grasp_map, gamma, phi, ref)
    call(Q.singular_value_metrics, gmap)
    call(Q.contact_weights, s, delta, tol)
    call(Q.gramian, s, gamma, phi, delta, tol=tol, ref=ref)
    call(Q.continuum_operator, s, gamma, phi, delta, tol=tol, ref=ref)
    call(Q.grasp_quality, s, gamma, phi, delta, tol=tol, ref=ref, finite=lambda q: [q.W, q.Q1, q.Q2, q.Q3, q.contact_length])
    call(Q.metrics_from_gramian, W, length, finite=lambda q: [q.W, q.Q1, q.Q2, q.Q3, q.eigenvalues])


@FAST
@given(tol=st.one_of(st.none(), num(0.0, 1.0)), ref=st.one_of(st.just((0.0, 0.0)), vector(0, 3)),
       st_=st.one_of(st.just("state"), bad), b=any_boundary)
def test_quality_of_state(tol, ref, st_, b) -> None:  # type: ignore[no-untyped-def]
    shape = A.shape_from_curvature(np.linspace(0, 10, 21), np.full(21, 1 / 6.0), C.base_pose(CIRCLE, 1.0, np.pi / 2, 0.0))
    state_ = C.sense(shape, CIRCLE, 0.5, tol=0.1) if isinstance(st_, str) and st_ == "state" else st_
    call(Q.quality_of_state, state_, b, tol=tol, ref=ref, finite=lambda q: [q.W, q.Q1, q.Q2, q.Q3])


# ----------------------------------------------------------------------------- feedback
@QUICK
@given(rho=st.one_of(num(0.0, 0.1), vector(0, 5)), alpha=st.one_of(num(0.0, 3.2), vector(0, 5)), mu1=num(0.0, 10.0),
       mu2=num(-5.0, 5.0), ei=st.one_of(num(0.0, 1.0), vector(0, 5)), lu=st.one_of(st.just(0.01), num(0.0, 1.0)),
       radius=st.one_of(num(0.0, 0.02), vector(0, 5)), r_obj=num(0.0, 0.05), kbar=num(0.0, 50.0))
def test_feedback_laws(rho, alpha, mu1, mu2, ei, lu, radius, r_obj, kbar) -> None:  # type: ignore[no-untyped-def]
    call(F.adaptive_mu2, radius, r_obj, length_unit=lu)
    call(F.curvature_feedback, rho, alpha, mu1, mu2, length_unit=lu)
    call(F.feedback_couple, rho, alpha, ei, mu1, mu2, length_unit=lu)
    call(F.feedback_couple_gradient, rho, alpha, ei, mu1, mu2, length_unit=lu)
    call(F.equilibrium_distance, kbar, mu2, length_unit=lu)
    call(F.lyapunov, rho, alpha, mu2, kbar)
    call(F.lyapunov_rate, alpha, mu1)


@settings(max_examples=15, deadline=None)
@given(rho0=num(0.0, 0.03), alpha0=num(0.0, 3.2), s=st.one_of(st.just(np.linspace(0.0, 0.2, 41)), grid(6)),
       mu1=num(0.0, 5.0), mu2=num(-1.0, 2.0), k_o=num(0.0, 60.0), s_o0=num(-1.0, 1.0))
def test_closed_loop_kinematics(rho0, alpha0, s, mu1, mu2, k_o, s_o0) -> None:  # type: ignore[no-untyped-def]
    call(F.closed_loop_kinematics, rho0, alpha0, s, mu1, mu2, k_o, s_o0=s_o0,
         finite=lambda k: [k.rho, k.alpha, k.kappa, k.s_o])


# ----------------------------------------------------------------------------- optimal grasps
@FAST
@given(b=any_boundary, **{k: v for k, v in state.items() if k != "s_o"}, s_o0=num(-40.0, 40.0),
       nodes=st.one_of(st.integers(-1, 40), st.just(10**12), bad), chi=st.one_of(num(0.0, 100.0), st.just(1e300)),
       rho_d=st.one_of(st.none(), num(0.0, 2.0), vector(0, 5), st.just(1e300)), alpha_d=st.one_of(num(0.0, 3.0), vector(0, 5)),
       table_size=st.one_of(st.just(4096), st.integers(-5, 100), bad), margins=st.one_of(st.just((1e-3,) * 3), vector(0, 4)),
       penalty=st.one_of(st.just(1e3), num(0.0, 1e4)), arm=st.one_of(st.none(), st.just(A.Arm(10.0, 0.5)), bad))
def test_grasp_problem(b, rho, alpha, s_o0, nodes, chi, rho_d, alpha_d, table_size, margins, penalty, arm) -> None:  # type: ignore[no-untyped-def]
    call(O.grasp_problem, b, rho0=rho, alpha0=alpha, s_o0=s_o0, nodes=nodes, chi=chi, rho_d=rho_d, alpha_d=alpha_d,
         table_size=table_size, margins=margins, penalty=penalty, arm=arm, finite=lambda p: [p.disc.x0, p.disc.rho_d])


@FAST
@given(name=st.one_of(st.sampled_from(["circle", "ellipse", "deformed", "square", ""]), bad),
       nodes=st.one_of(st.integers(-1, 40), bad), rho0=num(0.0, 8.0), base=st.one_of(st.just(A.BasePose(8.0, 0.0, np.pi / 2)), bad))
def test_paper_problem_and_problem_from_base(name, nodes, rho0, base) -> None:  # type: ignore[no-untyped-def]
    call(O.paper_problem, name, nodes=nodes, rho0=rho0, finite=lambda p: [p.disc.x0])
    call(O.problem_from_base, CIRCLE, base, nodes=30, finite=lambda p: [p.disc.x0])


PROBLEM = O.paper_problem("circle", nodes=40)
problems = st.one_of(st.just(PROBLEM), st.just(PROBLEM), bad)
controls = st.one_of(st.just(np.zeros(40)), st.just(np.full(40, 0.05)), vector(0, 40), st.just(np.full(40, 1e300)),
                     st.lists(st.floats(-1, 1), min_size=40, max_size=40).map(np.array))


def result_values(r: O.GraspResult) -> list[Any]:
    return [r.kappa, r.rho, r.alpha, r.s_o, r.costates, r.cost, r.residual]


@FAST
@given(problem=problems, initial=st.one_of(st.none(), st.sampled_from(["approach", "zero", "warm", "nope"]), controls),
       tol=st.one_of(st.just(1e-6), num(0.0, 1.0)), max_iterations=st.one_of(st.integers(-2, 30), bad),
       max_outer=st.one_of(st.just(15), st.integers(-1, 3), bad), constraint_tol=st.one_of(st.just(1e-8), num(0.0, 1.0)),
       hessian=st.one_of(st.sampled_from(["exact", "gauss-newton", "newton"]), bad),
       coarse=st.one_of(st.just(-1), st.none(), st.integers(-3, 30), bad), cost_tol=st.one_of(st.none(), num(0.0, 1.0)),
       coarse_tol=st.one_of(st.just(1.0), num(0.0, 10.0)))
def test_solve(problem, initial, tol, max_iterations, max_outer, constraint_tol, hessian, coarse, cost_tol, coarse_tol) -> None:  # type: ignore[no-untyped-def]
    if isinstance(initial, str) and initial == "warm":
        initial = O.solve(PROBLEM, max_iterations=3)
    call(O.solve, problem, initial=initial, tol=tol, max_iterations=max_iterations, max_outer=max_outer,
         constraint_tol=constraint_tol, hessian=hessian, coarse=coarse, cost_tol=cost_tol, coarse_tol=coarse_tol,
         finite=result_values)


@FAST
@given(problem=problems, eta=st.one_of(st.just(1e-3), num(0.0, 1.0)), max_iterations=st.one_of(st.integers(-2, 20), bad),
       gradient=st.one_of(st.sampled_from(["paper", "exact", "adjoint"]), bad), initial=st.one_of(st.none(), controls),
       tol=st.one_of(st.just(1e-6), num(0.0, 1.0)), target_cost=st.one_of(st.none(), num(-1.0, 1e3)),
       time_budget=st.one_of(st.none(), st.just(5.0), num(0.0, 5.0)))
def test_sweep_solver(problem, eta, max_iterations, gradient, initial, tol, target_cost, time_budget) -> None:  # type: ignore[no-untyped-def]
    call(O.forward_backward, problem, eta=eta, max_iterations=max_iterations, gradient=gradient, initial=initial, tol=tol,
         target_cost=target_cost, time_budget=time_budget, finite=result_values)


@pytest.mark.heavy
@FAST
@given(name=st.sampled_from(["circle", "ellipse", "deformed"]), rho0=st.floats(1e-9, 200.0), alpha0=st.floats(1e-9, np.pi - 1e-9),
       s_o0=st.floats(-100.0, 100.0), chi=st.floats(1e-9, 1e9), rho_d=st.one_of(st.none(), st.floats(-5.0, 50.0)),
       alpha_d=st.floats(-10.0, 10.0), solver=st.sampled_from(["fast", "fast-zero", "forward-backward"]))
def test_solvers_on_random_valid_problems(name, rho0, alpha0, s_o0, chi, rho_d, alpha_d, solver) -> None:  # type: ignore[no-untyped-def]
    """Valid but extreme problems: the solvers return finite results (converged or not) or a
    ContgraspError (e.g. an initial state with 1 + rho kappa_o <= 0 on the deformed circle)."""
    kw = {} if rho_d is None else {"rho_d": rho_d}
    problem = call(O.paper_problem, name, nodes=30, rho0=rho0, alpha0=alpha0, s_o0=s_o0, chi=chi, alpha_d=alpha_d, **kw,
                   finite=lambda p: [p.disc.x0])
    if problem is None:
        return
    if solver == "forward-backward":
        call(O.forward_backward, problem, eta=1e-3, max_iterations=20, finite=result_values)
    else:
        call(O.solve, problem, initial="zero" if solver == "fast-zero" else None, max_iterations=40, finite=result_values)


@QUICK
@given(problem=problems, kappa=controls, frozen=st.booleans(), penalty=st.booleans())
def test_cost_and_gradient(problem, kappa, frozen, penalty) -> None:  # type: ignore[no-untyped-def]
    call(O.cost, problem, kappa)
    call(O.gradient, problem, kappa, frozen=frozen, penalty=penalty)


# ----------------------------------------------------------------------------- quality maps
spec_fields = dict(
    object=st.one_of(st.sampled_from(["circle", "ellipse", "deformed", "square"]), bad),
    psi_steps=st.one_of(st.integers(-1, 4), st.just(10**12), bad),
    d_steps=st.one_of(st.integers(-1, 4), st.just(10**12), bad),
    d_min=num(0.0, 5.0), d_max=st.one_of(num(0.0, 14.0), st.just(1e300)),
    nodes=st.one_of(st.integers(-1, 60), st.just(10**12), bad),
    chi=num(0.0, 20.0), rho_d=num(0.0, 2.0), alpha_d=num(0.0, 3.2), arm_radius=num(0.0, 2.0),
    length_fraction=num(0.0, 1.0), contact_tol=num(0.0, 0.2), solver_tol=num(0.0, 1e-3),
)


@QUICK
@given(**spec_fields)
def test_map_spec(**kw) -> None:  # type: ignore[no-untyped-def]
    call(S.MapSpec, **kw, finite=lambda sp: [sp.psi, sp.d])


SPEC = S.MapSpec("circle", psi_steps=1, d_steps=1, d_min=3.0, d_max=3.0, nodes=40)


@FAST
@given(b=any_boundary, psi=num(-10.0, 10.0), d=st.one_of(num(0.0, 20.0), st.just(1e300), st.just(1e120)),
       spec=st.one_of(st.just(SPEC), bad))
def test_disc_pose_and_solve_pose(b, psi, d, spec) -> None:  # type: ignore[no-untyped-def]
    call(S.disc_pose, b, psi, d, finite=lambda p: [p.x, p.y, p.theta])
    call(S.solve_pose, spec, psi, d, finite=lambda r: [r.psi, r.d])


@FAST
@given(spec=st.one_of(st.just(SPEC), bad), executor=st.one_of(st.sampled_from(["serial", "threads", "dask", ""]), bad),
       workers=st.one_of(st.none(), st.integers(-2, 0), st.just(10**9), bad), metric=st.one_of(st.sampled_from(["Q4", "q1", ""]), bad))
def test_quality_map_options(spec, executor, workers, metric) -> None:  # type: ignore[no-untyped-def]
    # every combination drawn here has a bad value, so nothing is computed
    assume(not (isinstance(spec, S.MapSpec) and isinstance(executor, str) and executor == "serial" and workers is None))
    call(S.quality_map, spec, executor=executor, workers=workers, progress=False)
    call(S.maximise, _tiny_map() if isinstance(spec, S.MapSpec) else spec, metric)


@FAST
@given(npz=st.one_of(st.binary(max_size=64), st.just(b"PK\x03\x04garbage")), meta=st.one_of(
    st.binary(max_size=32).map(lambda b: b.decode("latin-1")), st.just("{}"), st.just("[]"), st.just('{"spec": 5}'),
    st.just('{"spec": {"object": "circle", "psi_steps": -1}}'), st.just('{"spec": {"object": "circle"}}')),
       other=st.sampled_from([None, 5, ["a"], "/nonexistent/map"]))
def test_load_map(files, npz, meta, other) -> None:  # type: ignore[no-untyped-def]
    base = files["tmp"] / "map"
    base.with_suffix(".npz").write_bytes(npz)
    base.with_suffix(".json").write_text(meta)
    call(S.load_map, base, finite=lambda m: [m.psi, m.d])
    call(S.load_map, other, finite=lambda m: [m.psi, m.d])


@pytest.mark.parametrize("target", ["under_file", "npz_is_dir"])
def test_save_map_to_an_unwritable_path(files, target) -> None:  # type: ignore[no-untyped-def]
    if target == "npz_is_dir":
        (files["tmp"] / "taken.npz").mkdir(exist_ok=True)
        path = files["tmp"] / "taken"
    else:
        path = files["under_file"]
    assert call(S.save_map, _tiny_map(), path, finite=lambda p: []) is None


_MAP: list[S.QualityMap] = []


def _tiny_map() -> S.QualityMap:
    if not _MAP:
        _MAP.append(S.quality_map(SPEC, executor="serial", optimise=False))
    return _MAP[0]


# ----------------------------------------------------------------------------- recordings
needs_bag = pytest.mark.skipif(not BAG.is_file(), reason="bags/paper_grasp.mcap is not present")


def _corrupt(files: dict[str, Path], how: str, cut: float, pos: float, junk: bytes) -> Any:
    d = files["tmp"] / "corrupt"
    if d.exists():
        shutil.rmtree(d)
    d.mkdir()
    data = files["bag"].read_bytes()
    if how == "cut":
        (d / "x.mcap").write_bytes(data[: int(cut * len(data))])
        return d / "x.mcap"
    if how == "flip":
        b = bytearray(data)
        b[min(int(pos * len(b)), len(b) - 1)] ^= 0x5A
        (d / "x.mcap").write_bytes(bytes(b))
        return d / "x.mcap"
    if how == "junk":
        (d / "x.mcap").write_bytes(junk)
        return d / "x.mcap"
    if how == "magic+junk":
        (d / "x.mcap").write_bytes(b"\x89MCAP0\r\n" + junk + b"\x89MCAP0\r\n")
        return d / "x.mcap"
    if how == "empty_dir":
        return d
    return {"missing": d / "nope.mcap", "none": None, "int": 7, "list": ["a"], "nul": "a\0b"}[how]


corruptions = dict(
    how=st.sampled_from(["cut", "flip", "junk", "magic+junk", "empty_dir", "missing", "none", "int", "list", "nul"]),
    cut=st.floats(0.0, 0.999), pos=st.floats(0.0, 1.0), junk=st.binary(max_size=200),
)


@needs_bag
@FAST
@given(**corruptions)
def test_open_recording_and_info(files, how, cut, pos, junk) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.bag.reader import info, open_recording

    rec = call(open_recording, _corrupt(files, how, cut, pos, junk), finite=lambda r: [])
    if rec is not None:  # a flip inside an unchecked byte (e.g. padding) may leave a readable file
        call(info, rec, finite=lambda i: [i["sim_time_s"] or i["wall_time_s"] or 0.0, i["message_count"]])


@needs_bag
@settings(max_examples=12, deadline=None)
@given(**corruptions, out=st.sampled_from(["new.mcap", "new_folder", "exists", "under_file"]))
def test_recover(files, how, cut, pos, junk, out) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.bag.reader import recover

    src = _corrupt(files, how, cut, pos, junk)
    dst = {"new.mcap": files["tmp"] / "rec" / "new.mcap", "new_folder": files["tmp"] / "rec" / "folder",
           "exists": files["dir"], "under_file": files["binary"] / "x.mcap"}[out]
    if (files["tmp"] / "rec").exists():
        shutil.rmtree(files["tmp"] / "rec")
    (files["tmp"] / "rec").mkdir()
    call(recover, src, dst, finite=lambda r: [r["messages"], r["chunks_kept"]])


@needs_bag
@settings(max_examples=10, deadline=None)
@given(**corruptions)
def test_analyze_recording(files, how, cut, pos, junk) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.recordings.analysis import analyze

    call(analyze, _corrupt(files, how, cut, pos, junk), finite=lambda r: [])


@needs_bag
@pytest.mark.parametrize("kw", [{"sensor_tolerance": "x"}, {"csv_dir": 5}, {"plot": 5}, {"quality_tolerance": float("nan")}])
def test_analyze_overrides_of_the_wrong_type(files, kw) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.recordings.analysis import analyze

    assert call(analyze, files["bag"], **kw, finite=lambda r: []) is None


@QUICK
@given(layout=st.one_of(*[st.sampled_from(["folder", "file"])] * 4, bad),
       compression=st.one_of(*[st.sampled_from(["zstd", "lz4", "none"])] * 4, bad),
       chunk_size=st.one_of(*[st.integers(1024, 1 << 20)] * 4, st.integers(-10, 1 << 31), bad),
       max_bag_duration=st.one_of(num(-5.0, 5.0), st.just(1e300)), max_bag_size=st.one_of(st.integers(-10, 1 << 51), bad))
def test_bag_writer_options(files, layout, compression, chunk_size, max_bag_duration, max_bag_size) -> None:  # type: ignore[no-untyped-def]
    from contgrasp_ros.bag.writer import BagWriter

    path = files["tmp"] / f"w_{uuid.uuid4().hex}{'.mcap' if isinstance(layout, str) and layout == 'file' else ''}"
    w = call(BagWriter, path, layout=layout, compression=compression, chunk_size=chunk_size,
             max_bag_duration=max_bag_duration, max_bag_size=max_bag_size, finite=lambda w: [])
    if w is not None:
        w.add_topic("/chatter", "std_msgs/msg/String")
        w.write("/chatter", b"\x00\x01\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00", 1)
        assert w.close()["message_count"] == 1


# ----------------------------------------------------------------------------- the CLI
def run_cli(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    """``contgrasp ARGV`` must fail with exit code 2 and one line on stderr (module docstring)."""
    from contgrasp_core.cli import main

    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: usage line + error line
            err = capsys.readouterr().err
            assert exc.code == 2, (argv, exc.code, err)
            assert "error:" in err.strip().splitlines()[-1] and "Traceback" not in err, (argv, err)
            return
    out, err = capsys.readouterr()
    shown = [w for w in caught if not issubclass(w.category, DeprecationWarning | PendingDeprecationWarning)]
    assert not shown, (argv, [str(w.message) for w in shown])
    assert code == 2, (argv, code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("contgrasp ") and "error" in lines[0], (argv, err)
    assert "Traceback" not in err and out == "", (argv, out, err)


BAD_NUMBERS = ["nan", "inf", "-inf", "-1", "0", "1e300", "-1e300", "x", "", "1,5"]
BAD_COUNTS = ["0", "-3", "1000000000000", "2.5", "x", "nan"]


def command(fixed: list[str], options: dict[str, tuple[Any, Any]], draw: Any) -> list[str]:
    """``fixed`` plus, for every option, maybe a valid value (strategy or None: no valid value);
    at least one option gets a bad value (strategy or None: never bad)."""
    names = sorted(options)
    bad_opts = draw(st.lists(st.sampled_from([n for n in names if options[n][1] is not None]), min_size=1, max_size=2,
                             unique=True))
    argv = list(fixed)
    for name in names:
        good, wrong = options[name]
        if name in bad_opts:
            value = draw(wrong)
        elif good is not None and draw(st.booleans()):
            value = draw(good)
        else:
            continue
        argv += [name] if value is True else [name, str(value)]
    if draw(st.booleans()):
        argv.append("--json")
    return argv


def paths(files: dict[str, Path], *names: str) -> st.SearchStrategy[str]:
    return st.sampled_from([str(files[n]) for n in names])


@st.composite
def kinematics_argv(draw: Any, files: dict[str, Path]) -> list[str]:
    bad_outline = paths(files, *(n for n in BAD_FILES if n != "open"))  # (an open outline closes implicitly: valid)
    bad_curvature = st.one_of(st.sampled_from(["wobbly", "const:", "const:x", "const:nan", "const:1e300", "parallel:x",
                                               "parallel:inf", "parallel:1e300"]),
                              paths(files, "dir", "empty", "binary", "garbage", "comment", "header_only", "nan", "one_column"))
    opts = {
        "--object": (st.sampled_from(["circle", "ellipse", "deformed"]), st.sampled_from(["square", "points", ""])),
        "--outline": (None, bad_outline),
        "--rho0": (st.sampled_from(["0.5", "1", "2"]), st.sampled_from(BAD_NUMBERS[:-3] + ["x", "1e200"])),
        "--alpha0": (st.sampled_from(["1.2", "1.55"]), st.sampled_from(BAD_NUMBERS + ["3.2", "7"])),
        "--s-o0": (st.sampled_from(["0", "3.5", "-2"]), st.sampled_from(["nan", "inf", "1e300", "x"])),
        "--length": (st.sampled_from(["5", "10"]), st.sampled_from(BAD_NUMBERS)),
        "--nodes": (st.sampled_from(["41", "101"]), st.sampled_from(BAD_COUNTS + ["1"])),
        "--curvature": (st.sampled_from(["parallel", "parallel:0.01"]), bad_curvature),
        "--tol": (st.sampled_from(["0", "0.1"]), st.sampled_from(["nan", "inf", "-1", "x", "1e400"])),
        "--plot": (None, st.sampled_from([str(files["tmp"] / "k.xyz"), str(files["under_file"]), str(files["dir"])])),
    }
    return command(["kinematics"], opts, draw)


@st.composite
def grasp_argv(draw: Any, files: dict[str, Path]) -> list[str]:
    opts = {
        "--object": (st.sampled_from(["circle", "deformed"]), st.sampled_from(["points", "square"])),
        "--rho0": (st.sampled_from(["4", "5"]), st.sampled_from(BAD_NUMBERS[:-3] + ["x", "1e200"])),
        "--alpha0": (st.sampled_from(["1.5"]), st.sampled_from(BAD_NUMBERS + ["3.2"])),
        "--s-o0": (st.sampled_from(["0", "2"]), st.sampled_from(["nan", "inf", "1e300", "x"])),
        "--chi": (st.sampled_from(["10", "1"]), st.sampled_from(BAD_NUMBERS)),
        "--nodes": (st.sampled_from(["60", "100"]), st.sampled_from(BAD_COUNTS + ["2"])),
        "--solver": (st.sampled_from(["fast", "forward-backward"]), st.sampled_from(["newton", ""])),
        "--eta": (st.sampled_from(["1e-6", "0.01"]), st.sampled_from(["nan", "inf", "-inf", "-1", "0", "-1e300", "x"])),
        "--gradient": (st.sampled_from(["paper", "exact"]), st.sampled_from(["adjoint"])),
        "--max-iterations": (st.sampled_from(["5", "50"]), st.sampled_from(["0", "-3", "2.5", "x"])),
        "--tol": (st.sampled_from(["1e-6", "1e-9"]), st.sampled_from(["nan", "inf", "-1", "0", "x"])),
        "--plot": (None, st.sampled_from([str(files["tmp"] / "g.xyz"), str(files["under_file"]), str(files["dir"])])),
    }
    return command(["grasp"], opts, draw)


@st.composite
def quality_argv(draw: Any, files: dict[str, Path]) -> list[str]:
    opts = {
        "--object": (st.sampled_from(["circle", "ellipse"]), st.sampled_from(["square"])),
        "--psi-steps": (st.sampled_from(["1", "2"]), st.sampled_from(BAD_COUNTS)),
        "--d-steps": (st.sampled_from(["1", "2"]), st.sampled_from(BAD_COUNTS)),
        "--d-min": (st.sampled_from(["3", "4"]), st.sampled_from(BAD_NUMBERS + ["20"])),
        "--d-max": (st.sampled_from(["5", "13"]), st.sampled_from(BAD_NUMBERS + ["1000"])),
        "--nodes": (st.sampled_from(["40"]), st.sampled_from(BAD_COUNTS + ["1"])),
        "--contact-tol": (st.sampled_from(["0.05"]), st.sampled_from(["nan", "inf", "-1", "x"])),
        "--metric": (st.sampled_from(["Q1", "all"]), st.sampled_from(["Q4"])),
        "--executor": (st.sampled_from(["serial"]), st.sampled_from(["threads"])),
        "--workers": (st.sampled_from(["1"]), st.sampled_from(["0", "-1", "1000000000", "x"])),
        "--load": (None, paths(files, "missing", "dir", "binary", "empty")),
        "--out": (None, st.sampled_from([str(files["under_file"]), str(files["binary"] / "m")])),
        "--plot": (None, st.sampled_from([str(files["tmp"] / "q.xyz"), str(files["under_file"])])),
    }
    argv = command(["quality-map"], opts, draw)
    if "--executor" not in argv and "--workers" not in argv:
        argv += ["--executor", "serial"]  # were every value accepted, no process pool would start
    return argv


@st.composite
def figures_argv(draw: Any, files: dict[str, Path]) -> list[str]:
    opts = {
        "--nodes": (st.sampled_from(["60"]), st.sampled_from(BAD_COUNTS + ["2"])),
        "--psi-steps": (st.sampled_from(["2"]), st.sampled_from(BAD_COUNTS)),
        "--d-steps": (st.sampled_from(["2"]), st.sampled_from(BAD_COUNTS)),
        "--out": (st.just(str(files["tmp"] / "figs")), st.sampled_from([str(files["binary"]), str(files["under_file"])])),
        "--no-maps": (st.just(True), None),
    }
    return command(["figures"], opts, draw)


@st.composite
def simulate_argv(draw: Any, files: dict[str, Path]) -> list[str]:
    opts = {
        "--object": (st.sampled_from(["circle", "circle:0.02", "ellipse:0.03,0.02", "deformed"]),
                     st.sampled_from(["circle:x", "circle:-1", "circle:nan", "circle:1,2", "ellipse:0.5,0.5", "ellipse:0.03,x",
                                      "ellipse:0,1", "deformed:inf", "square", "", ":"])),
        "--duration": (st.sampled_from(["0.5"]), st.sampled_from(["nan", "inf", "-1", "0", "x"])),
        "--control-period": (st.sampled_from(["0.01"]), st.sampled_from(["nan", "inf", "-1", "0", "x"])),
        "--dt": (st.sampled_from(["0.01"]), st.sampled_from(["nan", "inf", "-1", "0", "x"])),
        "--nodes": (st.sampled_from(["21"]), st.sampled_from(BAD_COUNTS + ["2"])),
        "--damping": (st.sampled_from(["1"]), st.sampled_from(["nan", "inf", "-1", "x"])),
        "--contact-tol": (st.sampled_from(["0.5"]), st.sampled_from(["nan", "inf", "-1", "x"])),
        "--plot": (None, st.sampled_from([str(files["tmp"] / "s.xyz"), str(files["under_file"]), str(files["dir"])])),
        "--animate": (None, st.sampled_from([str(files["tmp"] / "a.mp4"), str(files["dir"]), str(files["under_file"])])),
    }
    return command(["simulate"], opts, draw)


def _bag_paths(files: dict[str, Path], recoverable: bool = True) -> st.SearchStrategy[str]:
    """Recordings that cannot be opened; ``recoverable``: also a truncated and a corrupted one
    (which ``bag recover`` repairs, so they are bad input only for the other commands)."""
    names = ["missing", "dir", "binary", "empty"] + [n for n in ("bad_meta", "garbage_meta") if n in files]
    names += [n for n in ("cut", "flip") if recoverable and n in files]
    return paths(files, *names)


@st.composite
def bag_argv(draw: Any, files: dict[str, Path]) -> list[str]:
    sub = draw(st.sampled_from(["info", "recover", "replay", "analyze"]))
    bad_bag = _bag_paths(files)
    if sub == "info":
        return ["bag", "info", draw(bad_bag)] + draw(st.sampled_from([[], ["--json"]]))
    if sub == "recover":
        if "cut" in files and draw(st.booleans()):  # a readable input, an output that cannot be written
            out = draw(st.sampled_from([str(files["dir"]), str(files["under_file"]), str(files["binary"] / "o.mcap")]))
            return ["bag", "recover", str(files["cut"]), out]
        return ["bag", "recover", draw(_bag_paths(files, recoverable=False)), str(files["tmp"] / "never" / "out.mcap")]
    good_bag = st.just(str(files["bag"])) if "bag" in files else bad_bag
    if sub == "replay":
        opts = {
            "--rate": (st.sampled_from(["1", "50"]), st.sampled_from(["nan", "inf", "-1", "0", "1e300", "x"])),
            "--start": (st.sampled_from(["0"]), st.sampled_from(["nan", "inf", "-1", "x", "1e300"])),
            "--end": (st.sampled_from(["100"]), st.sampled_from(["nan", "inf", "-1", "x", "1e300"])),
            "--delay": (st.sampled_from(["0"]), st.sampled_from(["nan", "inf", "-1", "x", "1e300"])),
            "--topics": (st.just("/clock"), st.sampled_from(["/nope", "''"])),
        }
        if draw(st.booleans()):
            return ["replay", draw(bad_bag), "--delay", "0"]
        return command(["replay", draw(good_bag)], opts, draw)
    if draw(st.booleans()) or "bag" not in files:
        return ["analyze", draw(bad_bag)]
    opts = {
        "--plot": (None, st.sampled_from([str(files["tmp"] / "a.xyz"), str(files["under_file"]), str(files["dir"])])),
        "--csv": (None, st.sampled_from([str(files["binary"]), str(files["under_file"])])),
    }
    return command(["analyze", draw(good_bag)], opts, draw)


CLI_SETTINGS = settings(max_examples=40, deadline=None,
                        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.mark.heavy
@CLI_SETTINGS
@given(data=st.data())
def test_cli_kinematics(files, capsys, data) -> None:  # type: ignore[no-untyped-def]
    run_cli(capsys, data.draw(kinematics_argv(files)))


@CLI_SETTINGS
@given(data=st.data())
def test_cli_grasp(files, capsys, data) -> None:  # type: ignore[no-untyped-def]
    run_cli(capsys, data.draw(grasp_argv(files)))


@CLI_SETTINGS
@given(data=st.data())
def test_cli_quality_map(files, capsys, data) -> None:  # type: ignore[no-untyped-def]
    run_cli(capsys, data.draw(quality_argv(files)))


@settings(CLI_SETTINGS, max_examples=10)
@given(data=st.data())
def test_cli_figures(files, capsys, data) -> None:  # type: ignore[no-untyped-def]
    run_cli(capsys, data.draw(figures_argv(files)))
    assert not (files["tmp"] / "figs").exists() or not any((files["tmp"] / "figs").iterdir())


@CLI_SETTINGS
@given(data=st.data())
def test_cli_simulate(files, capsys, data) -> None:  # type: ignore[no-untyped-def]
    run_cli(capsys, data.draw(simulate_argv(files)))


@CLI_SETTINGS
@given(data=st.data())
def test_cli_recordings(files, capsys, data) -> None:  # type: ignore[no-untyped-def]
    run_cli(capsys, data.draw(bag_argv(files)))
    assert not (files["tmp"] / "never").exists()  # a bad input creates no output


def test_cli_json_output_has_no_nan(capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A result holding numpy NaN scalars prints valid JSON (null), not a traceback."""
    import json

    from contgrasp_core.cli import kinematics as cli_kinematics

    monkeypatch.setattr(cli_kinematics, "run", lambda args: {"x": np.float64("nan"), "y": [np.float32(np.inf)]})
    from contgrasp_core.cli import main

    assert main(["kinematics", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"x": None, "y": [None]}


def test_dataclass_results_are_checked() -> None:
    """The property helper really looks into results (a NaN inside fails)."""
    @dataclasses.dataclass
    class R:
        v: np.ndarray

    with pytest.raises(AssertionError):
        call(lambda: R(np.array([np.nan])), finite=lambda r: [r.v])
