"""Grasp-quality maps over arm base poses and their maximisation (paper Sec. IV-C, eq. (16)).

Base positions lie in the region D around the object: the point at boundary distance ``d`` on
the ray from the object frame origin at polar angle ``psi``, ``d in [d_min, d_max]``; the base
heading is ``theta0 = psi + pi/2`` (tangent to the disc, counter-clockwise). For each pose the
initial contact state comes from closest-point projection, the inner optimal grasp
(eq. (9)) is solved by :func:`contgrasp_core.optimal.solve`, and Q1..Q3 of its
contact set are evaluated (:mod:`contgrasp_core.quality`).

Work is split into one task per ``psi``: along it the distances are solved in increasing order,
each warm-started from its neighbour's solution. The task is pure (same inputs, same
arithmetic), so serial, process-pool and Dask executors give identical maps.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ._validate import MAX_NODES, instance, integer, real
from .arm import Arm, BasePose
from .blas import single_thread_blas
from .boundary import Boundary
from .errors import ContgraspError, InvalidParameterError, RunFailure, WriteError
from .objects import FIG2_SCALE, ObjectSpec
from .quality import grasp_quality

if TYPE_CHECKING:  # (imported lazily at run time)
    from .optimal import GraspProblem

__all__ = [
    "MapSpec",
    "PoseResult",
    "QualityMap",
    "disc_pose",
    "solve_pose",
    "optimal_grasp",
    "quality_map",
    "maximise",
    "best_grid_pose",
    "TIE_RTOL",
    "map_paths",
    "save_map",
    "load_map",
    "METRICS",
]

METRICS = ("Q1", "Q2", "Q3")
NO_BASE, BAD_START = "no base pose", "invalid initial state"
"""How a pose's reason starts when its inner problem was never solved (:attr:`QualityMap.n_solves`)."""
MAX_MAP_STEPS = 100_000
"""Largest psi_steps / d_steps of a map."""
MAX_MAP_SIZE = 100_000_000
"""Largest psi_steps * d_steps * nodes (the stored arm centrelines: 16 bytes each)."""
Array = NDArray[np.float64]


@dataclass(frozen=True)
class MapSpec:
    """What to sweep: the object (an :class:`ObjectSpec`, or its text such as ``"ellipse"`` or
    ``"circle:4"``, in the paper's dimensionless units), the (psi, d) grid of D and the inner
    problem's settings. The object frame origin must lie inside the object (bases are placed on
    rays from it).

    Paper defaults (Sec. IV-C): d in [3, 13], arm of constant unit radius and length L_o/2,
    rho_d = 1, alpha_d = pi/2, chi = 10. ``arm_radius_tip`` tapers the arm linearly from
    ``arm_radius`` at the base (Sec. III-A's arm; None: constant); ``rho_d = None`` tracks the
    arm's own radius r(s) (Sec. III-A's choice). ``contact_tol`` is the contact tolerance of
    Definition 1 used for Q1..Q3 (delta >= -tol); since rho_d equals the arm radius the depth
    hovers around zero, so a small positive tolerance (default 0.05 = 5 % of the radius)
    counts the tracked part of the arm as in contact. ``nodes`` is the inner grid size.
    """

    object: ObjectSpec = ObjectSpec.parse("circle")
    psi_steps: int = 24
    d_steps: int = 6
    d_min: float = 3.0
    d_max: float = 13.0
    nodes: int = 200
    chi: float = 10.0
    rho_d: float | None = 1.0
    alpha_d: float = 0.5 * np.pi
    arm_radius: float = 1.0
    arm_radius_tip: float | None = None
    length_fraction: float = 0.5
    contact_tol: float = 0.05
    solver_tol: float = 1e-8

    def __post_init__(self) -> None:
        psi_steps = integer("psi_steps", self.psi_steps, lo=1, hi=MAX_MAP_STEPS)
        d_steps = integer("d_steps", self.d_steps, lo=1, hi=MAX_MAP_STEPS)
        nodes = integer("nodes", self.nodes, lo=3, hi=MAX_NODES)
        if psi_steps * d_steps * nodes > MAX_MAP_SIZE:
            raise InvalidParameterError(
                f"psi_steps * d_steps * nodes = {psi_steps * d_steps * nodes:.3g} exceeds {MAX_MAP_SIZE:.0e} "
                "(the map keeps every arm shape in memory)"
            )
        d_min = real("d_min", self.d_min, lo=0.0, lo_open=True)
        d_max = real("d_max", self.d_max, lo=0.0, lo_open=True)
        if not d_min <= d_max:
            raise InvalidParameterError(f"need 0 < d_min <= d_max, got [{self.d_min}, {self.d_max}]")
        for name in ("chi", "rho_d", "arm_radius", "arm_radius_tip", "length_fraction", "solver_tol"):
            if getattr(self, name) is not None or name not in ("rho_d", "arm_radius_tip"):
                real(name, getattr(self, name), lo=0.0, lo_open=True)
        real("alpha_d", self.alpha_d, lo=0.0, hi=np.pi, lo_open=True, hi_open=True)
        real("contact_tol", self.contact_tol, lo=0.0)
        object.__setattr__(self, "object", ObjectSpec.coerce(self.object, FIG2_SCALE))
        boundary = self.object.boundary()
        check_origin_inside(self.object, boundary)
        reach = self.length_fraction * boundary.length
        if d_max >= reach:
            raise InvalidParameterError(
                f"d_max = {d_max:g} must be less than the arm length {reach:.6g} (= length_fraction * L_o): "
                "a base farther from the object cannot touch it; give a smaller d_max (--d-max) or a larger object"
            )

    def boundary(self) -> Boundary:
        return self.object.boundary()

    def to_dict(self) -> dict[str, Any]:
        """Plain types (the object as :meth:`ObjectSpec.to_dict`); ``MapSpec(**d)`` rebuilds it."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["object"] = self.object.to_dict()
        return out

    @property
    def psi(self) -> Array:
        return np.linspace(0.0, 2.0 * np.pi, self.psi_steps, endpoint=False)

    @property
    def d(self) -> Array:
        return np.linspace(self.d_min, self.d_max, self.d_steps)


@dataclass(frozen=True)
class PoseResult:
    """Outcome at one base pose: Q1..Q3 (NaN when invalid) and why/how."""

    psi: float
    d: float
    base: tuple[float, float, float]
    valid: bool
    reason: str
    Q: tuple[float, float, float] = (np.nan, np.nan, np.nan)
    converged: bool = False
    constraints_ok: bool = False
    iterations: int = 0
    contact_length: float = 0.0
    seconds: float = 0.0
    x: Array | None = field(default=None, repr=False)
    y: Array | None = field(default=None, repr=False)


def _ray_distance(boundary: Boundary, direction: Array, lam: float) -> float:
    return float(boundary.project(np.array([lam * direction])).signed_distance[0])


ORIGIN_OUTSIDE = "the object frame origin must lie inside the object to place bases in D"
"""Why an object has no base poses: bases are placed on rays from the origin (:func:`disc_pose`)."""


def check_origin_inside(obj: ObjectSpec, boundary: Boundary) -> None:
    """Refuse an object whose frame origin (0, 0) is not inside it (an input error, one line
    naming the object, the origin's distance outside and where the object's centre is)."""
    outside = _ray_distance(boundary, np.zeros(2), 0.0)
    if outside >= 0:
        cx, cy = obj.reference
        raise InvalidParameterError(
            f"{ORIGIN_OUTSIDE}: (0, 0) lies {outside:.4g} outside {obj.text()}, whose centre is at "
            f"({round(cx, 4) + 0.0:g}, {round(cy, 4) + 0.0:g}); shift the object so that it surrounds the origin"
        )


def disc_pose(boundary: Boundary, psi: float, d: float) -> BasePose:
    """Base pose in D: on the ray at polar angle ``psi`` from the origin, at boundary distance ``d``.

    Heading ``theta0 = psi + pi/2``. Requires the origin inside the object (true for the paper's
    objects, which are star-shaped about it).
    """
    from scipy.optimize import brentq

    instance("boundary", boundary, Boundary)
    psi = real("psi", psi)
    d = real("d", d, lo=0.0, lo_open=True)
    if d > 1e100:
        raise InvalidParameterError(f"d must be <= 1e100, got {d!r}")
    u = np.array([np.cos(psi), np.sin(psi)])
    if _ray_distance(boundary, u, 0.0) >= 0:
        raise InvalidParameterError(ORIGIN_OUTSIDE)
    _, pts = boundary.sample(256)
    r_max = float(np.max(np.hypot(*pts.T))) + boundary.length / 256
    lam_b = brentq(lambda lam: _ray_distance(boundary, u, lam), 0.0, r_max, xtol=1e-13)
    lo, hi = lam_b + d, r_max + d
    f_lo = _ray_distance(boundary, u, lo) - d
    lam = lo if f_lo >= 0 else brentq(lambda lam: _ray_distance(boundary, u, lam) - d, lo, hi, xtol=1e-12)
    return BasePose(float(lam * u[0]), float(lam * u[1]), float(psi + 0.5 * np.pi))


def _problem(spec: MapSpec, boundary: Boundary, base: BasePose) -> GraspProblem:
    from .optimal import problem_from_base

    arm = Arm(spec.length_fraction * boundary.length, spec.arm_radius, spec.arm_radius_tip)
    return problem_from_base(
        boundary, base, arm=arm, nodes=spec.nodes, rho_d=spec.rho_d, alpha_d=spec.alpha_d, chi=spec.chi
    )


def optimal_grasp(spec: MapSpec, boundary: Boundary, base: BasePose, warm: Any = None) -> tuple[GraspProblem, Any]:
    """The inner optimal grasp (eq. (9)) from ``base``: the warm start ``warm`` first, the
    solver's own cold starts as fall-backs (deterministic order); the first converged solution
    within the constraints, else the first one found. :class:`ContgraspError` when the initial
    state is invalid ("invalid initial state: ...") or no start solves ("inner solve failed: ...")."""
    from .optimal import solve

    try:
        problem = _problem(spec, boundary, base)
    except ContgraspError as exc:
        raise InvalidParameterError(f"{BAD_START}: {exc}") from exc
    res, errors = None, []
    for initial in ([warm] if warm is not None else []) + ["approach", "zero"]:
        try:
            cand = solve(problem, initial=initial, tol=spec.solver_tol)
        except ContgraspError as exc:
            errors.append(str(exc))
            continue
        if res is None or (cand.converged and cand.constraints.ok):
            res = cand
        if res.converged and res.constraints.ok:
            break
    if res is None:
        raise RunFailure(f"inner solve failed: {errors[-1]}")
    return problem, res


def _evaluate(spec: MapSpec, boundary: Boundary, psi: float, d: float, base: BasePose, warm: Any) -> tuple[PoseResult, Any]:
    try:
        problem, res = optimal_grasp(spec, boundary, base, warm)
    except ContgraspError as exc:
        return PoseResult(psi, d, (base.x, base.y, base.theta), False, str(exc)), None
    s = problem.s
    delta = problem.arm.radius(s) - res.rho
    q = grasp_quality(s, boundary.point(res.s_o), boundary.tangent_angle(res.s_o), delta, tol=spec.contact_tol)
    ok = bool(res.converged and res.constraints.ok)
    reason = "ok" if ok else ("not converged" if not res.converged else "constraints violated")
    return (
        PoseResult(
            psi,
            d,
            (base.x, base.y, base.theta),
            ok,
            reason,
            Q=(q.Q1, q.Q2, q.Q3) if ok else (np.nan, np.nan, np.nan),
            converged=bool(res.converged),
            constraints_ok=bool(res.constraints.ok),
            iterations=int(res.iterations),
            contact_length=q.contact_length,
            x=res.shape.r[:, 0],
            y=res.shape.r[:, 1],
        ),
        res if ok else None,
    )


def solve_pose(spec: MapSpec, psi: float, d: float, warm: Any = None) -> PoseResult:
    """Inner optimal grasp and Q1..Q3 at the base pose (psi, d) of D."""
    instance("spec", spec, MapSpec)
    boundary = spec.boundary()
    return _evaluate(spec, boundary, psi, d, disc_pose(boundary, psi, d), warm)[0]


def _column(spec: MapSpec, psi: float) -> list[PoseResult]:
    """All distances at one polar angle, in increasing d, each warm-started from the previous."""
    with single_thread_blas():
        boundary = spec.boundary()
        out, warm = [], None
        for d in spec.d:
            try:
                base = disc_pose(boundary, psi, d)
            except ContgraspError as exc:
                out.append(PoseResult(psi, d, (np.nan, np.nan, np.nan), False, f"{NO_BASE}: {exc}"))
                continue
            t0 = time.perf_counter()
            res, sol = _evaluate(spec, boundary, psi, float(d), base, warm)
            warm = sol if sol is not None else warm
            out.append(replace(res, seconds=time.perf_counter() - t0))
        return out


@dataclass(frozen=True)
class QualityMap:
    """Q1..Q3 on the (psi, d) grid (NaN where invalid) with per-pose status and the optimum."""

    spec: MapSpec
    psi: Array
    d: Array
    Q: Array  # (3, P, D)
    valid: NDArray[np.bool_]
    reasons: list[list[str]]
    base: Array  # (P, D, 3)
    iterations: NDArray[np.int_]
    arms: Array  # (P, D, 2, nodes) arm centrelines (NaN where invalid)
    seconds: Array  # (P, D) wall seconds per pose (inner solve + quality)
    wall_time: float
    executor: str
    optimum: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def n_solves(self) -> int:
        """Grid poses whose inner problem was solved (not those without a base pose or with an
        invalid initial state; the maximisation's evaluations are counted apart)."""
        return sum(not r.startswith((NO_BASE, BAD_START)) for row in self.reasons for r in row)

    def to_dict(self) -> dict[str, Any]:
        def grid(a: Array) -> list[list[float | None]]:
            return [[None if not np.isfinite(v) else float(v) for v in row] for row in a]

        return {
            "object": self.spec.object.text(),
            "psi": self.psi.tolist(),
            "d": self.d.tolist(),
            "Q1": grid(self.Q[0]),
            "Q2": grid(self.Q[1]),
            "Q3": grid(self.Q[2]),
            "valid": self.valid.tolist(),
            "invalid_reasons": sorted({r for row in self.reasons for r in row if r != "ok"}),
            "n_valid": int(self.valid.sum()),
            "optimum": self.optimum,
            "wall_time_s": self.wall_time,
            "n_solves": self.n_solves,
            "executor": self.executor,
            "spec": self.spec.to_dict(),
        }




def _run_columns(spec: MapSpec, executor: str, workers: int | None, scheduler: str | None, progress: bool) -> list[list[PoseResult]]:
    from functools import partial

    from .executors import run_tasks

    psis = [float(p) for p in spec.psi]
    return list(run_tasks(partial(_column, spec), psis, executor, workers=workers, scheduler=scheduler,
                          progress=f"quality map {spec.object.text()}" if progress else None, unit="psi"))


def quality_map(
    spec: MapSpec,
    *,
    executor: str = "processes",
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = False,
    optimise: bool = True,
) -> QualityMap:
    """Compute the quality map of ``spec`` (and, with ``optimise``, each metric's maximiser)."""
    instance("spec", spec, MapSpec)
    if not isinstance(executor, str) or executor not in ("serial", "processes", "dask"):
        raise InvalidParameterError(f"unknown executor {executor!r}: serial, processes or dask")
    if workers is not None:
        # more processes than polar angles would only idle
        workers = min(integer("workers", workers, lo=1, hi=MAX_WORKERS), spec.psi_steps)
    t0 = time.perf_counter()
    cols = _run_columns(spec, executor, workers, scheduler, progress)
    P, D = spec.psi_steps, spec.d_steps
    Q = np.full((3, P, D), np.nan)
    valid = np.zeros((P, D), dtype=bool)
    base = np.full((P, D, 3), np.nan)
    iters = np.zeros((P, D), dtype=int)
    arms = np.full((P, D, 2, spec.nodes), np.nan)
    seconds = np.zeros((P, D))
    reasons = [["" for _ in range(D)] for _ in range(P)]
    for i, col in enumerate(cols):
        for j, r in enumerate(col):
            Q[:, i, j] = r.Q
            valid[i, j] = r.valid
            base[i, j] = r.base
            iters[i, j] = r.iterations
            reasons[i][j] = r.reason
            seconds[i, j] = r.seconds
            if r.valid and r.x is not None and r.y is not None:
                arms[i, j, 0], arms[i, j, 1] = r.x, r.y
    qm = QualityMap(spec, spec.psi, spec.d, Q, valid, reasons, base, iters, arms, seconds, 0.0, executor)
    optimum = {m: maximise(qm, m) for m in METRICS} if optimise and valid.any() else {}
    return replace(qm, wall_time=time.perf_counter() - t0, optimum=optimum)


MAX_WORKERS = 1024


TIE_RTOL = 1e-6
"""Relative tolerance under which two quality values count as a tie (see :func:`maximise`)."""


def best_grid_pose(grid: Array, rtol: float = TIE_RTOL) -> tuple[int, int]:
    """Index (i, j) of the best grid pose of ``grid`` (psi x d, -inf where invalid) with a
    deterministic tie rule: among the poses within ``rtol`` (relative) of the maximum, the
    smallest polar angle psi, then the smallest distance d.

    A circle's map is invariant under rotating the base about the centre (and an ellipse's under
    a half turn), so a plain argmax would pick whichever psi the last digits of the solves
    favour; this rule picks the same pose on every run."""
    best = float(np.max(grid))
    ties = grid >= best - rtol * abs(best) if np.isfinite(best) else grid == best
    i, j = np.unravel_index(int(np.argmax(ties)), grid.shape)  # first True in (psi, d) order
    return int(i), int(j)


def maximise(qm: QualityMap, metric: str) -> dict[str, Any]:
    """Nelder-Mead maximisation of one metric over D (eq. (16)), from the best grid point.

    The search variables are (psi, d) with d bounded to [d_min, d_max] (scipy's bounded
    Nelder-Mead); psi is periodic. Invalid poses count as -inf quality.

    The base's heading ``theta`` is given in [0, 2 pi), as psi.

    Ties (the optimum of a rotation-invariant map is a whole ring of poses): the start is the
    grid pose of :func:`best_grid_pose` (smallest psi among values within :data:`TIE_RTOL` of
    the best, then smallest d), and Nelder-Mead's result replaces it only if it is better by more
    than :data:`TIE_RTOL` (relative); so a circle's optimum is reported at the smallest grid psi,
    on every run.
    """
    from scipy.optimize import minimize

    instance("qm", qm, QualityMap)
    if not isinstance(metric, str) or metric not in METRICS:
        raise InvalidParameterError(f"metric must be one of {METRICS}, got {metric!r}")
    k = METRICS.index(metric)
    spec = qm.spec
    grid = np.where(qm.valid, qm.Q[k], -np.inf)
    i, j = best_grid_pose(grid)
    boundary = spec.boundary()
    cache: dict[tuple[float, float], PoseResult] = {}

    def value(z: Array) -> float:
        psi, d = float(np.mod(z[0], 2 * np.pi)), float(np.clip(z[1], spec.d_min, spec.d_max))
        key = (round(psi, 12), round(d, 12))
        if key not in cache:
            try:
                base = disc_pose(boundary, psi, d)
                cache[key] = _evaluate(spec, boundary, psi, d, base, None)[0]
            except ContgraspError as exc:
                cache[key] = PoseResult(psi, d, (np.nan,) * 3, False, str(exc))
        r = cache[key]
        return -r.Q[k] if r.valid else np.inf

    z0 = np.array([qm.psi[i], qm.d[j]])
    dpsi = 2 * np.pi / spec.psi_steps
    dd = (spec.d_max - spec.d_min) / max(spec.d_steps - 1, 1) if spec.d_max > spec.d_min else 0.0
    simplex = np.array([z0, z0 + [0.5 * dpsi, 0.0], z0 + [0.0, 0.5 * dd if dd else 0.0]])
    simplex[:, 1] = np.clip(simplex[:, 1], spec.d_min, spec.d_max)
    if dd and simplex[2, 1] == simplex[0, 1]:
        simplex[2, 1] = z0[1] - 0.5 * dd
    res = minimize(
        value,
        z0,
        method="Nelder-Mead",
        bounds=[(None, None), (spec.d_min, spec.d_max)],
        options={"initial_simplex": simplex, "xatol": 1e-3, "fatol": 1e-9 * max(1.0, abs(grid[i, j])), "maxfev": 120},
    )
    psi, d = float(np.mod(res.x[0], 2 * np.pi)), float(np.clip(res.x[1], spec.d_min, spec.d_max))
    best = cache.get((round(psi, 12), round(d, 12)))
    grid_best = float(grid[i, j])
    if best is None or not best.valid or best.Q[k] <= grid_best + TIE_RTOL * abs(grid_best):
        psi, d = float(qm.psi[i]), float(qm.d[j])
        best = cache.get((round(psi, 12), round(d, 12))) or solve_pose(spec, psi, d)
    return {
        "psi": psi,
        "d": d,
        "value": float(best.Q[k]),
        "grid_value": grid_best,
        "base": {"x": best.base[0], "y": best.base[1], "theta": float(np.mod(best.base[2], 2 * np.pi))},  # (like psi)
        "evaluations": int(res.nfev),
        "x": None if best.x is None else best.x.tolist(),
        "y": None if best.y is None else best.y.tolist(),
    }


MAP_SUFFIXES = (".npz", ".json")
"""The two files of a saved map: the arrays and the metadata."""


def map_paths(path: str | Path) -> tuple[Path, Path]:
    """The files ``FILE.npz`` and ``FILE.json`` a map named ``path`` is saved in: ``path`` is
    ``FILE`` itself or one of the two files; any other suffix is part of the name and kept
    (``map.v2`` -> ``map.v2.npz``, ``egg.csv`` -> ``egg.csv.json``), so no other file is replaced."""
    p = Path(path)
    if not p.name:
        raise InvalidParameterError(f"a quality map needs a file name, got {str(path)!r}")
    base = p.with_suffix("") if p.suffix in MAP_SUFFIXES else p
    npz, meta = (base.with_name(base.name + suffix) for suffix in MAP_SUFFIXES)
    return npz, meta


def save_map(qm: QualityMap, path: str | Path) -> Path:
    """Save to :func:`map_paths` of ``path`` (.npz arrays, .json metadata and optimum); the .npz path."""
    p, meta_path = map_paths(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            p, psi=qm.psi, d=qm.d, Q=qm.Q, valid=qm.valid, base=qm.base, iterations=qm.iterations, arms=qm.arms,
            seconds=qm.seconds, reasons=np.array(qm.reasons, dtype=str),
        )
        meta = {k: v for k, v in qm.to_dict().items() if k not in ("Q1", "Q2", "Q3", "valid")}
        meta_path.write_text(json.dumps(meta, indent=1))
    except OSError as exc:
        raise WriteError(f"cannot save the quality map to {p}: {exc.strerror or exc}") from exc
    return p


def load_map(path: str | Path) -> QualityMap:
    """Reload a map saved by :func:`save_map` under the same name (no recomputation)."""
    try:
        p, meta_path = map_paths(path)
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"cannot load quality map {path!r}: not a file path ({exc})") from exc
    for f in (p, meta_path):  # (the map's arrays first: a typo names the file the user meant)
        if not f.is_file():
            raise InvalidParameterError(f"cannot load quality map {path}: no file {f} "
                                        "(a map is FILE.npz with FILE.json beside it, as --out writes them)")
    try:
        meta = json.loads(meta_path.read_text())
        with np.load(p) as z:
            arrays = {k: z[k] for k in z.files}
        spec = MapSpec(**meta["spec"])
        qm = QualityMap(
            spec, arrays["psi"], arrays["d"], arrays["Q"], arrays["valid"], arrays["reasons"].tolist(), arrays["base"],
            arrays["iterations"], arrays["arms"], arrays["seconds"], float(meta["wall_time_s"]), str(meta["executor"]),
            meta.get("optimum", {}),
        )
        P, D = spec.psi_steps, spec.d_steps
        shapes = {"psi": (P,), "d": (D,), "Q": (3, P, D), "valid": (P, D), "base": (P, D, 3)}
        bad = [k for k, shape in shapes.items() if np.shape(arrays[k]) != shape]
        if bad or not isinstance(qm.optimum, dict):
            raise ValueError(f"arrays {bad} do not match the map's grid {P} x {D}")
    except ContgraspError as exc:
        raise InvalidParameterError(f"cannot load quality map {p}: invalid settings ({exc})") from exc
    except OSError as exc:
        raise InvalidParameterError(f"cannot load quality map {p}: cannot read {exc.filename or p}: {exc.strerror or exc}") from exc
    except Exception as exc:  # noqa: BLE001 - any failure to parse the files means a corrupt map
        raise InvalidParameterError(f"cannot load quality map {p}: {type(exc).__name__}: {exc}") from exc
    return qm
