"""Do the paper's quality measures predict how firmly a grasp holds? (beyond the paper)

For every base pose of a quality map (paper Sec. IV-C) and the map's optima, :func:`run_study`
takes the static map's Q1-Q3 (eq. (9)'s optimal grasp), then places the rod at the same pose in
metres, runs its closed loop to settlement and measures Q1-Q3 of the settled contact, the grasp
stiffness and the holding capacity (:func:`contgrasp_core.holding.measure_holding`). Poses run as
independent tasks (:mod:`contgrasp_core.executors`), each result appended to a JSON-lines file
(an interrupted study resumes); :func:`correlations` gives Spearman's rank correlations with
bootstrap intervals. docs/holding.md, "The study".
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field, replace
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np
from filelock import FileLock, Timeout

from ..arm import BasePose
from ..errors import ContgraspError, InvalidParameterError, RunFailure, WriteError
from ..control.hold_law import HOLDING_LAWS, LAWS, HoldLawSettings, check_law_settings
from ..executors import run_tasks
from .experiment import GraspFailure, HoldSettings, measure_holding
from ..objects import FIG2_SCALE, OUTLINE, SHAPES, SYNTAX, ObjectSpec
from ..quality_map import MapSpec, QualityMap, quality_map
from ..scenario import PAPER, Scenario

__all__ = ["ARMS", "StudySpec", "PREDICTORS", "RESPONSES", "run_study", "load_results", "correlations", "study_pose",
           "expand_symmetric", "pose_scenario"]

PREDICTORS = ("static_Q1", "static_Q2", "static_Q3", "static_QH", "cage_QH", "Q1", "Q2", "Q3", "Q1_force", "Q2_force",
              "Q3_force", "bound_min")
"""The quality measures: the static map's (the paper's optimal grasp) Q1-Q3 and wrench capacity
Q_H (:func:`contgrasp_core.holding.measure.static_capacity`, with the study's friction), the
wrench capacity of the holding law's cage at rest (``cage_QH``,
:func:`contgrasp_core.holding.measure.cage_capacity`: before simulating too; NaN for the
paper's law), the settled grasp's, the settled grasp's weighted by its contact forces
(:func:`contgrasp_core.holding.force_weighted_quality`), and the settled grasp's friction bound
``p_max h(d)`` (:func:`contgrasp_core.holding.experiment.friction_bound`, its pressure at rest) in the
weakest of the measured directions (a diagnostic after simulating: does friction at the rest
pressure set the capacity?)."""
RESPONSES = ("stiffness_min", "stiffness_det", "capacity_min", "grasped")
"""The holding measures: lambda_min and det of K's scaled symmetric part, the worst capacity
(over the poses that grasped), and whether the closed loop made a settled grasp that held at all
(1 or 0, over every pose: only the static map's measures exist for the poses that did not)."""


NUMERICS = {name: version(name) for name in ("numpy", "scipy", "numba")}
"""The numerical libraries' versions, recorded in every result row: a static map's marginal
poses can change with them (docs/holding.md, the kidney's map between sessions)."""

ARMS = ("map", "rod")
"""The study's arms (module docstring)."""


@dataclass(frozen=True)
class StudySpec:
    """The study of one object (``object``: a built-in shape in the paper's units, e.g.
    ``circle`` or ``ellipse``, or ``outline:FILE.csv`` in the paper's units about an origin inside
    it): the map grid, ``scale`` (m per paper unit), the rod's ``nodes``,
    how long the closed loop may take to settle (``duration``, s: the rod scenario's 4 s leave
    some close poses still creeping at just above the settle speed), how each grasp is loaded
    (``hold``: its ``support`` 0 releases the object entirely free), the closed loop's ``law``
    (``paper`` or ``hold``, docs/holding.md) and the arm's length as a fraction of the object's
    perimeter (``length_fraction``: the map's and the rod's; 0.5 the paper's map) or the rod
    scenario's arm (``arm``: module docstring), and the holding law's depth regulation
    (``depth_gain``, 1/s, docs/holding.md (H7); 0: none) and dwell (``dwell``, s, (H8); 0:
    none), and the arm's muscles' ``max_muscle_stress`` (Pa; 0: unbounded, docs/rod.md)."""

    object: str = "circle"
    psi_steps: int = 24
    d_steps: int = 6
    d_min: float = 3.0
    d_max: float = 13.0
    scale: float = 0.005
    nodes: int = 51
    duration: float = 8.0
    hold: HoldSettings = field(default_factory=lambda: HoldSettings(directions=4))
    law: str = "paper"
    length_fraction: float = 0.5
    arm: str = "map"
    depth_gain: float = 0.0
    dwell: float = 0.0
    max_muscle_stress: float = 0.0

    def __post_init__(self) -> None:
        if self.arm not in ARMS:
            raise InvalidParameterError(f"unknown arm {self.arm!r}; the arms are {', '.join(ARMS)}")
        if self.arm == "rod" and self.length_fraction != StudySpec.length_fraction:
            raise InvalidParameterError("the length fraction sets the map's arm only; the rod's arm has its own length "
                                        f"({PAPER.rod.length:g} m)")
        object.__setattr__(self, "object", self.object_spec().text())  # (one name: "circle" is "circle:5")
        self.map_spec()  # validates the grid
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise InvalidParameterError(f"scale must be a finite number > 0 (m per paper unit), got {self.scale!r}")
        if int(self.nodes) != self.nodes or not 3 <= self.nodes <= 1001:
            raise InvalidParameterError(f"nodes must be an integer in [3, 1001], got {self.nodes!r}")
        replace(PAPER.rod, max_muscle_stress=self.max_muscle_stress)  # (validates it)
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise InvalidParameterError(f"duration must be a finite number > 0 (s), got {self.duration!r}")
        if self.law not in LAWS:
            raise InvalidParameterError(f"unknown law {self.law!r}; the laws are {', '.join(LAWS)}")
        check_law_settings(self.law, self.hold_law())  # (also validates the depth gain and the dwell)

    def hold_law(self) -> HoldLawSettings:
        """The holding law's settings of every pose: the defaults with the study's depth gain and dwell."""
        return HoldLawSettings(depth_gain=self.depth_gain, dwell=self.dwell)

    def object_spec(self) -> ObjectSpec:
        """The object in the paper's units (a built-in shape or an outline)."""
        if not isinstance(self.object, str):
            raise InvalidParameterError(f"the study's object must be text, {SYNTAX} or outline:FILE.csv; "
                                        f"got {self.object!r}")
        return ObjectSpec.parse(self.object, FIG2_SCALE)

    def map_spec(self) -> MapSpec:
        """The static quality map's specification (paper units)."""
        obj = self.object_spec()
        arm: dict[str, Any] = {"length_fraction": self.length_fraction}
        if self.arm == "rod":
            rod = PAPER.rod
            arm = {"length_fraction": rod.length / self.scale / obj.boundary().length,
                   "arm_radius": rod.radius_base / self.scale, "arm_radius_tip": rod.radius_tip / self.scale, "rho_d": None}
        return MapSpec(object=obj, psi_steps=self.psi_steps, d_steps=self.d_steps, d_min=self.d_min, d_max=self.d_max, **arm)

    def distinct_rows(self) -> int:
        """How many polar-angle rows of the grid differ: a rotation of the object onto itself by
        ``2 pi k / psi_steps`` maps row ``i`` onto row ``i + k`` (the rod engine, the law, the
        sensing and Q1-Q3's eigenvalues do not depend on the frame's orientation), so rows
        ``0 .. distinct_rows() - 1`` are measured and the others follow
        (:func:`expand_symmetric`): 1 for a circle, ``psi_steps / 2`` for an ellipse (its half
        turn), ``psi_steps / gcd(lobes, psi_steps)`` for a deformed circle."""
        spec = self.object_spec()
        if spec.shape == OUTLINE:
            return self.psi_steps
        p = dict(zip(SHAPES[spec.shape], spec.params, strict=True))
        if spec.shape == "circle" or (spec.shape == "ellipse" and p["a"] == p["b"]) or (
                spec.shape == "deformed" and p["amplitude"] == 0):
            return 1
        order = 2 if spec.shape == "ellipse" else int(p["lobes"]) if float(p["lobes"]).is_integer() else 1
        return self.psi_steps // math.gcd(max(order, 1), self.psi_steps)

    def rod_object(self) -> ObjectSpec:
        """The object in metres: the paper's shape scaled by ``scale`` about the object frame's
        origin, placed at the rod scenario's object centre."""
        spec = self.object_spec()
        if spec.shape == OUTLINE:
            c = np.asarray(PAPER.object.center)
            return replace(spec, points=tuple(map(tuple, (self.scale * np.asarray(spec.points) + c).tolist())), source="")
        params = tuple(p * self.scale if name in ("R", "a", "b") else p
                       for name, p in zip(SHAPES[spec.shape], spec.params, strict=True))
        return ObjectSpec(spec.shape, params, PAPER.object.center, spec.angle)


def base_si(spec: StudySpec, base_paper: tuple[float, float, float]) -> tuple[float, float, float]:
    """A base pose in the paper's units about the object (x, y, heading) on the rod scenario
    (m about the scenario's object centre, rad)."""
    x, y, heading = base_paper
    cx, cy = PAPER.object.center
    return cx + spec.scale * x, cy + spec.scale * y, float(heading)


def pose_scenario(spec: StudySpec, base_paper: tuple[float, float, float]) -> Scenario:
    """The rod scenario of one pose (module docstring, step 2): the study's arm at the base
    ``base_paper`` (x, y, heading in the paper's units about the object)."""
    x, y, heading = base_si(spec, base_paper)
    obj = spec.rod_object()
    rod = replace(PAPER.rod, n_elements=spec.nodes - 1, base_position=(x, y), base_angle=heading,
                  max_muscle_stress=spec.max_muscle_stress)
    if spec.arm == "map":
        ms = spec.map_spec()
        rod = replace(rod, length=ms.length_fraction * obj.boundary().length, radius_base=ms.arm_radius * spec.scale,
                      radius_tip=ms.arm_radius * spec.scale)
    return PAPER.with_object(obj, rod=rod, loop=replace(PAPER.loop, duration=spec.duration), law=spec.law,
                             hold_law=spec.hold_law())


def study_pose(spec: StudySpec, key: str, base_paper: tuple[float, float, float],
               static_q: tuple[float, float, float]) -> dict[str, Any]:
    """One pose of the study: the grasp from the base ``base_paper`` (x, y, heading in the
    paper's units about the object frame) on the rod scenario, measured (a failed grasp is a
    result with its ``status``; so is a base the arm cannot start from, outcome ``refused``:
    :func:`contgrasp_core.scenario.check_start`)."""
    out: dict[str, Any] = {"key": key, "base": list(base_si(spec, base_paper)),
                           "static_Q1": static_q[0], "static_Q2": static_q[1], "static_Q3": static_q[2],
                           "versions": NUMERICS}
    t0 = time.perf_counter()
    try:
        scenario = pose_scenario(spec, base_paper)
    except InvalidParameterError as exc:  # (a --d-max beyond the arm's reach, say): one pose, not the study
        out.update(status=f"refused: {exc}", outcome="refused", seconds=time.perf_counter() - t0)
        return out
    try:
        result = measure_holding(scenario, spec.hold)
    except ContgraspError as exc:
        outcome = exc.outcome if isinstance(exc, GraspFailure) else "not held" if isinstance(exc, RunFailure) else "error"
        out.update(status=f"{type(exc).__name__}: {exc}", outcome=outcome, seconds=time.perf_counter() - t0)
        return out
    d = result.to_dict()
    if result.stiffness_eigenvalues is None:
        out.update(status=f"not held: {result.release_reason}", outcome="not held", seconds=time.perf_counter() - t0)
        return out
    eig = np.asarray(result.stiffness_eigenvalues)
    out.update(status="ok", outcome="held", seconds=time.perf_counter() - t0, Q1=result.Q1, Q2=result.Q2, Q3=result.Q3,
               Q1_force=d["Q1_force"], Q2_force=d["Q2_force"], Q3_force=d["Q3_force"],
               stiffness=d["stiffness"], stiffness_eigenvalues=d["stiffness_eigenvalues"],
               stiffness_min=float(eig[0]), stiffness_det=float(np.prod(eig)), capacity=d["capacity"],
               capacity_min=result.capacity_min, released_displacement=d["released_displacement"],
               pressure_max=result.pressure_max, settle_time_s=result.settle_time)
    return out


def _task(args: tuple[StudySpec, str, tuple[float, float, float], tuple[float, float, float]]) -> dict[str, Any]:
    return study_pose(*args)


def load_results(path: str | Path) -> list[dict[str, Any]]:
    """The poses done so far (the JSON-lines file of :func:`run_study`; [] if there is none)."""
    p = Path(path)
    if not p.exists():
        return []
    rows = []
    for n, line in enumerate(p.read_text().splitlines(), 1):
        if line.strip():
            try:
                row = json.loads(line)
            except json.JSONDecodeError as exc:
                raise InvalidParameterError(f"{p}:{n}: not a study result line ({exc.msg})") from exc
            if not (isinstance(row, dict) and isinstance(row.get("key"), str)):
                raise InvalidParameterError(f"{p}:{n}: not a study result line (an object with a text 'key')")
            if row["key"] != "spec" and not _is_base(row.get("base")):
                raise InvalidParameterError(f"{p}:{n}: not a study result line (its 'base' is not three finite numbers)")
            rows.append(row)
    return rows


def _is_base(value: Any) -> bool:
    return (isinstance(value, list) and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))


def run_study(spec: StudySpec, path: str | Path, *, executor: str = "processes", workers: int | None = None,
              scheduler: str | None = None, progress: bool = False) -> tuple[QualityMap, list[dict[str, Any]]]:
    """The static map, then every pose not yet in ``path`` (JSON lines, appended as results
    arrive): the grid poses ``grid:i,j`` of the distinct rows (:meth:`StudySpec.distinct_rows`)
    and the optima ``optimum:Q1|Q2|Q3``. Returns the map and all results (earlier ones
    included; :func:`expand_symmetric` fills in the rest of the grid). A file of another
    specification is refused first, before the map's minutes. One writer at a time: while a
    study holds the lock on ``path + ".lock"`` (an OS lock, released when it ends, even killed)
    another on the same file is refused with :class:`WriteError`."""
    p = Path(path)
    lock = FileLock(p.with_name(p.name + ".lock"), timeout=0)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        lock.acquire()
    except Timeout:
        raise WriteError(f"another holding study is writing to {p} (it holds {lock.lock_file}); let it finish, "
                         "or give another file") from None
    except OSError as exc:
        raise WriteError(f"cannot lock the study results {p}: {exc.strerror or exc}") from exc
    try:
        return _run_study(spec, p, executor, workers, scheduler, progress)
    finally:
        lock.release()


def _run_study(spec: StudySpec, p: Path, executor: str, workers: int | None, scheduler: str | None,
               progress: bool) -> tuple[QualityMap, list[dict[str, Any]]]:
    """:func:`run_study` with its file locked."""
    earlier = load_results(p)
    wanted = json.loads(json.dumps(_spec_dict(spec)))
    other = {k: v for k, v in earlier[0].items() if k != "key"} if earlier else dict(wanted)
    if isinstance(other.get("object"), str):  # (recorded by the name it was given: "circle" for "circle:5")
        other["object"] = _canonical_object(other["object"])
    if other != wanted:
        differ = sorted(k for k in set(other) | set(wanted) if other.get(k) != wanted.get(k))
        raise InvalidParameterError(f"{p} holds a study of another specification (it differs in {', '.join(differ)}); "
                                    "give the same options to resume it, or another file")
    qm = quality_map(spec.map_spec(), executor=executor, workers=workers, scheduler=scheduler, progress=progress)
    tasks = []
    for i in range(spec.distinct_rows()):
        for j in range(spec.d_steps):
            if qm.valid[i, j]:
                tasks.append((f"grid:{i},{j}", tuple(qm.base[i, j]), tuple(qm.Q[:, i, j])))
    for metric, opt in qm.optimum.items():
        b = opt["base"]
        k = ("Q1", "Q2", "Q3").index(metric)
        static = [np.nan, np.nan, np.nan]
        static[k] = opt["value"]
        tasks.append((f"optimum:{metric}", (b["x"], b["y"], b["theta"]), tuple(static)))
    done = {r["key"] for r in earlier}
    todo = [(spec, key, tuple(float(v) for v in base), tuple(float(v) for v in q))
            for key, base, q in tasks if key not in done]
    before = _before_simulating(spec, tasks)
    try:
        with p.open("a") as fh:
            if not done:
                fh.write(json.dumps({"key": "spec", **_spec_dict(spec)}) + "\n")
            for row in run_tasks(_task, todo, executor, workers=workers, scheduler=scheduler,
                                 progress=f"holding study {spec.object}" if progress else None, unit="pose"):
                for name, value in before.get(row["key"], _NOT_COMPUTED).items():
                    row.setdefault(name, value)
                fh.write(json.dumps(row, allow_nan=True) + "\n")
                fh.flush()
    except OSError as exc:
        raise WriteError(f"cannot write the study results to {p}: {exc.strerror or exc}") from exc
    return qm, _with_todays_map(spec, load_results(p), tasks, before)


def _with_todays_map(spec: StudySpec, results: list[dict[str, Any]],
                     tasks: list[tuple[str, tuple[float, ...], tuple[float, ...]]],
                     before: dict[str, dict[str, float]]) -> list[dict[str, Any]]:
    """The measured rows with the static predictors (Q1-Q3, Q_H, the cage's Q_H) of today's map, which the
    figure shows too; the file keeps what it recorded. A row whose base or static Q1-Q3 differ
    from today's (or whose pose is no longer valid in today's map, its predictors then NaN) is
    marked ``map_changed``: the map was computed differently when it ran (the inner solve's
    marginal poses can change with the numerical libraries or the machine)."""
    today = {key: (base, q) for key, base, q in tasks}
    out = []
    for r in results:
        if r["key"] == "spec":
            continue
        row = {**r, **before.get(r["key"], _NOT_COMPUTED)}
        if r["key"] in today:
            base, q = today[r["key"]]
            stored = [_value(r, f"static_Q{k}") for k in (1, 2, 3)]
            same = (np.allclose(r["base"], base_si(spec, (base[0], base[1], base[2])), rtol=0.0, atol=1e-9)
                    and np.allclose(stored, q, rtol=1e-6, atol=0.0, equal_nan=True))
            row.update(static_Q1=q[0], static_Q2=q[1], static_Q3=q[2])
        else:
            same = False
            row.update(static_Q1=float("nan"), static_Q2=float("nan"), static_Q3=float("nan"))
        if not same:
            row["map_changed"] = True
        out.append(row)
    return out


def _canonical_object(text: str) -> str:
    """The one name of the object a results file's specification names (as given, if it names none)."""
    try:
        return ObjectSpec.parse(text, FIG2_SCALE).text()
    except ContgraspError:
        return text


_NOT_COMPUTED = {"static_QH": math.nan, "cage_QH": math.nan}
"""The measures before simulating of a pose that has none (not among today's tasks). (NaN here
is ``math.nan``, one object, so rows compare equal run after run.)"""


def _before_simulating(spec: StudySpec, tasks: list[tuple[str, tuple[float, ...], tuple[float, ...]]]) -> dict[str, dict[str, float]]:
    """The wrench capacities before simulating of each task: ``static_QH`` of its optimal grasp
    (:func:`_static_capacities`) and, with the holding law, ``cage_QH`` of the law's cage at
    rest (:func:`contgrasp_core.holding.measure.cage_capacity`, SI; NaN where the rod's
    rest under the cage's law cannot be solved, and for the paper's law)."""
    from contgrasp_core.holding.measure import cage_capacity

    static = _static_capacities(spec, tasks)
    out = {}
    for key, base, _ in tasks:
        cage = math.nan
        if spec.law in HOLDING_LAWS:
            try:
                cage = cage_capacity(pose_scenario(spec, (base[0], base[1], base[2])), spec.hold.mu).measure
            except ContgraspError:
                pass
        out[key] = {"static_QH": static[key], "cage_QH": cage}
    return out


def _static_capacities(spec: StudySpec, tasks: list[tuple[str, tuple[float, ...], tuple[float, ...]]]) -> dict[str, float]:
    """Q_H of each task's optimal grasp (paper units), with the study's friction: for the grid
    poses the map's own grasps (each row warm-started along increasing distance, as the map
    solves them), for the optima from a cold start; NaN where the grasp cannot be solved."""
    from contgrasp_core.holding.measure import static_capacity, static_capacity_column

    ms, out = spec.map_spec(), {}
    rows: dict[int, list[tuple[int, str, tuple[float, ...]]]] = {}
    for key, base, _ in tasks:
        if key.startswith("grid:"):
            i, j = (int(v) for v in key[len("grid:"):].split(","))
            rows.setdefault(i, []).append((j, key, base))
        else:
            try:
                out[key] = static_capacity(ms, BasePose(*base), spec.hold.mu).measure
            except ContgraspError:
                out[key] = float("nan")
    for column in rows.values():
        column.sort()
        caps = static_capacity_column(ms, [BasePose(*base) for _, _, base in column], spec.hold.mu)
        out.update({key: float("nan") if cap is None else cap.measure for (_, key, _), cap in zip(column, caps, strict=True)})
    return out


_LATER_FIELDS = {"law": "paper", "length_fraction": 0.5, "arm": "map", "depth_gain": 0.0, "dwell": 0.0,
                 "max_muscle_stress": 0.0}
"""StudySpec's fields added after studies were recorded, with their defaults: written only when
they differ, so a file recorded before them resumes (it holds a study at those defaults)."""


def _spec_dict(spec: StudySpec) -> dict[str, Any]:
    """The study's specification as recorded; under law ``hold`` with the playback's settings
    (they change its results; and a file of the reactive law, recorded when it was named
    ``hold``, lacks them, so it is refused rather than resumed as the planned hold)."""
    d = asdict(spec)
    d["hold"] = asdict(spec.hold)
    for name, default in _LATER_FIELDS.items():
        if d[name] == default:
            del d[name]
    if spec.law == "hold":
        law = spec.hold_law()
        d["playback"] = {k: getattr(law, k) for k in ("plan_gain", "plan_damping", "plan_damping_time", "plan_squeeze",
                                                      "plan_squeeze_time")}
    return d


def expand_symmetric(spec: StudySpec, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` and, for every grid pose of a row beyond :meth:`StudySpec.distinct_rows`, the
    measured pose it is a rotation of, turned by that rotation about the object's centre (the
    base, K as ``R K R^T``, the capacity's directions and wrenches) and marked ``same_as``."""
    n = spec.distinct_rows()
    measured = {r["key"]: r for r in rows if r["key"].startswith("grid:")}
    cx, cy = PAPER.object.center
    out = list(rows)
    for i in range(n, spec.psi_steps):
        for j in range(spec.d_steps):
            src = measured.get(f"grid:{i % n},{j}")
            if src is None:
                continue
            phi = 2.0 * np.pi * (i - i % n) / spec.psi_steps
            c, s_ = np.cos(phi), np.sin(phi)
            rot = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            row = {**src, "key": f"grid:{i},{j}", "same_as": src["key"]}
            x, y, heading = src["base"]
            row["base"] = [cx + c * (x - cx) - s_ * (y - cy), cy + s_ * (x - cx) + c * (y - cy), heading + phi]
            if "stiffness" in src:
                row["stiffness"] = (rot @ np.asarray(src["stiffness"]) @ rot.T).tolist()
            if "capacity" in src:
                row["capacity"] = [{**cap, "direction": (rot @ np.asarray(cap["direction"])).tolist(),
                                    "wrench": (rot @ np.asarray(cap["wrench"])).tolist()} for cap in src["capacity"]]
            out.append(row)
    return out


def _value(row: dict[str, Any], name: str) -> float:
    if name == "grasped":
        return float(row.get("status") == "ok")
    if name == "bound_min" and name not in row:
        bounds = [c.get("friction_bound") for c in row.get("capacity", [])]
        return float(np.min(np.asarray(bounds, dtype=float))) if bounds and None not in bounds else float("nan")
    v = row.get(name)
    return float(v) if v is not None else float("nan")


def _spearman_rows(picks: np.ndarray) -> np.ndarray:
    """Spearman's rho of each resample ``picks[b]`` (shape ``(boot, n, 2)``): Pearson's
    correlation of the average ranks, NaN where a side does not vary (what
    ``scipy.stats.spearmanr`` gives one resample at a time, here all at once)."""
    from scipy.stats import rankdata

    ranks = rankdata(picks, axis=1)
    ranks -= ranks.mean(axis=1, keepdims=True)
    cov = np.einsum("bn,bn->b", ranks[:, :, 0], ranks[:, :, 1])
    var = np.einsum("bnk,bnk->bk", ranks, ranks)
    varies = np.all(np.ptp(picks, axis=1) > 0, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(varies, cov / np.sqrt(var[:, 0] * var[:, 1]), np.nan)


def correlations(rows: list[dict[str, Any]], *, boot: int = 2000, seed: int = 0,
                 grid_only: bool = True) -> dict[str, dict[str, dict[str, float]]]:
    """Spearman's rank correlation of each :data:`PREDICTORS` with each :data:`RESPONSES` over
    the measured poses (the symmetric copies of :func:`expand_symmetric` are left out; grid
    poses only unless ``grid_only`` is False): the holding measures over the poses that grasped
    (``status == "ok"``), ``grasped`` over every pose that ran (not those that failed with an
    error of the code), with a percentile bootstrap 95 % interval (``boot`` resamples of the
    poses): ``{predictor: {response: {"rho", "low", "high", "n"}}}``; rho is NaN below 4 poses
    or where one side does not vary."""
    from scipy.stats import spearmanr

    ran = [r for r in rows if r["key"] != "spec" and "same_as" not in r and r.get("outcome") != "error"
           and (not grid_only or r["key"].startswith("grid:"))]
    rng = np.random.default_rng(seed)
    out: dict[str, dict[str, dict[str, float]]] = {}
    for pred in PREDICTORS:
        out[pred] = {}
        for resp in RESPONSES:
            pool = ran if resp == "grasped" else [r for r in ran if r.get("status") == "ok"]
            pairs = np.array([(_value(r, pred), _value(r, resp)) for r in pool]).reshape(-1, 2)
            pairs = pairs[np.all(np.isfinite(pairs), axis=1)]
            n = len(pairs)
            if n < 4 or np.ptp(pairs[:, 0]) == 0 or np.ptp(pairs[:, 1]) == 0:
                out[pred][resp] = {"rho": float("nan"), "low": float("nan"), "high": float("nan"), "n": n}
                continue
            rho = float(spearmanr(pairs[:, 0], pairs[:, 1]).statistic)
            samples = _spearman_rows(pairs[rng.integers(0, n, (boot, n))])
            samples = samples[np.isfinite(samples)]
            low, high = np.percentile(samples, [2.5, 97.5]) if samples.size else (np.nan, np.nan)
            out[pred][resp] = {"rho": rho, "low": float(low), "high": float(high), "n": n}
    return out
