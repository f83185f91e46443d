"""Offline analysis of a recorded graph run (``contgrasp analyze BAG``), without ROS.

:func:`analyze` loads a recording (:mod:`~contgrasp_ros.recordings.run_data`), recomputes what the
nodes computed from its rod states (:mod:`~contgrasp_ros.recordings.recompute`), and
:func:`summarize` builds the launcher's summary plus the recomputation errors;
:func:`write_csv` and :func:`write_plots` export the run, :func:`check` says whether it is
genuine. Decimated recordings are paired by ``step``. Nothing here imports rclpy. docs/analysis.md.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from contgrasp_core.errors import ContgraspError, FailedResult, InvalidParameterError, WriteError, output_error
from contgrasp_core.objects import OUTLINE, ROD_SCALE, SHAPES, ObjectSpec, outline_text
from contgrasp_ros.plumbing import topics
from contgrasp_ros.launcher.summary import FinalQuality, FinalState, build_summary, contact_stats
from contgrasp_ros.recordings.recompute import (
    RECOMPUTE_BOUND,
    Recomputation,
    peak_couple_recomputed,
    recompute,
    recompute_parameters,
    settle_recomputed,
    step_gaps,
)
from contgrasp_ros.recordings.run_data import SIMULATOR, Array, IntArray, RunData, load_run, node_default

__all__ = [
    "summarize",
    "history",
    "object_name",
    "object_motion",
    "holding_under_pushes",
    "write_csv",
    "write_plots",
    "analyze",
    "check",
    "RecomputeMismatchError",
    "MixedRecordingError",
]


class RecomputeMismatchError(FailedResult):
    """The recording does not recompute: an error above :data:`RECOMPUTE_BOUND`, contact flags or
    quality validity that differ, or steps whose recomputation failed (``contgrasp analyze``
    prints the analysis, then the one error line, and exits 1)."""


class MixedRecordingError(FailedResult):
    """The recording holds two graphs' messages: one node's status came from two processes at
    once (another graph ran in the same domain and namespace); printed as
    :class:`RecomputeMismatchError`."""


def history(run: RunData, period: float = 0.01) -> list[dict[str, Any]]:
    """Snapshots for :func:`contgrasp_core.figures.run.run_figure`, picked like the launcher's monitor
    (a rod state and contact state of the same step, at least ``period`` s of sim time apart)."""
    c = run.contact
    if c is None:
        return []
    rod_at = {int(k): i for i, k in enumerate(run.rod.step)}
    out: list[dict[str, Any]] = []
    next_t = 0.0
    for j, k in enumerate(c.step):
        i = rod_at.get(int(k))
        t = float(c.t[j])
        if i is None or t + 1e-12 < next_t:
            continue
        next_t = t + period
        r, o = run.rod, run.rod.object
        out.append({"t": t, "x": r.x[i].tolist(), "y": r.y[i].tolist(), "theta": r.theta[i].tolist(),
                    "radius": r.radius[i].tolist(), "s": c.s[j].tolist(), "rho": c.rho[j].tolist(), "alpha": c.alpha[j].tolist(),
                    "object_q": [] if o is None else o.q[i].tolist(), "object_centroid": [] if o is None else o.centroid[i].tolist()})
    return out


def object_name(run: RunData) -> str | None:
    """The run's object as every ``contgrasp`` command names it
    (:meth:`~contgrasp_core.objects.ObjectSpec.text`, what ``--object`` takes back): from the
    recorded simulator parameters (``object`` in metres, or an outline by its ``object_outline``
    file, which need not be at hand), else from the recorded boundary when it is a built-in
    shape; None when the recording names it neither way (a curve without shape parameters)."""
    if run.params is not None:
        sim = run.params.get(SIMULATOR, {})
        text, outline = str(sim.get("object", node_default(SIMULATOR, "object"))), str(sim.get("object_outline", ""))
        if text == OUTLINE or outline:
            return outline_text(outline)
        return ObjectSpec.parse(text, ROD_SCALE).text()
    shape = {"deformed_circle": "deformed"}.get(run.boundary.kind, run.boundary.kind)
    if shape not in SHAPES:
        return None
    return ObjectSpec(shape, tuple(run.boundary.params[k] for k in SHAPES[shape])).text()


def object_motion(run: RunData) -> dict[str, Any] | None:
    """How a movable object moved and what pushed it, over the recorded rod states (None: the
    object is fixed): largest and final displacement of the centroid (m) and rotation (rad),
    final velocity, the external wrench held on it (largest force and torque, the times of
    the first and last state with a wrench, the final one), and the measured holding per
    constant push (:func:`holding_under_pushes`)."""
    o, t = run.rod.object, run.rod.t
    if o is None:
        return None
    dist = np.hypot(o.q[:, 0], o.q[:, 1])
    force = np.hypot(o.wrench[:, 0], o.wrench[:, 1])
    pushed = np.flatnonzero(np.any(o.wrench != 0.0, axis=1))
    i = int(np.argmax(dist))
    return {
        "mode": None if run.params is None else run.params.get(SIMULATOR, {}).get("object_mode"),
        "centroid": o.centroid[0].tolist(),
        "max_displacement": float(dist[i]),
        "max_displacement_t": float(t[i]),
        "max_rotation": float(np.abs(o.q[:, 2]).max()),
        "final_displacement": float(dist[-1]),
        "final_q": o.q[-1].tolist(),
        "final_v": o.v[-1].tolist(),
        "final_speed": float(np.hypot(o.v[-1, 0], o.v[-1, 1])),
        "wrench": {
            "max_force": float(force.max()),
            "max_torque": float(np.abs(o.wrench[:, 2]).max()),
            "first_t": float(t[pushed[0]]) if len(pushed) else None,
            "last_t": float(t[pushed[-1]]) if len(pushed) else None,
            "states": len(pushed),
            "final": o.wrench[-1].tolist(),
        },
        "holding": holding_under_pushes(t, o.q, o.v, o.wrench),
    }


def holding_under_pushes(t: Array, q: Array, v: Array, wrench: Array) -> list[dict[str, Any]]:
    """The grasp's measured holding in a recording: for each run of states holding the same
    non-zero wrench (a step or pulse; a ramp gives one run per state), the object's displacement
    from the state before the push to the run's last state, the secant compliances along the
    force (``(dq_xy . f) / |f|^2``, m/N) and for the torque (``dpsi / tau``, rad/(N m)) and the
    object's speed at the end (near zero: it came to rest, so the secant is the static one)."""
    out: list[dict[str, Any]] = []
    k, n = 0, len(t)
    while k < n:
        if not np.any(wrench[k] != 0.0):
            k += 1
            continue
        end = k
        while end + 1 < n and np.array_equal(wrench[end + 1], wrench[k]):
            end += 1
        before = max(k - 1, 0)
        dq = q[end] - q[before]
        w = wrench[k]
        f2 = float(w[0] ** 2 + w[1] ** 2)
        out.append({"t_start": float(t[k]), "t_end": float(t[end]), "wrench": w.tolist(), "displacement": dq.tolist(),
                    "compliance_force": float(dq[:2] @ w[:2] / f2) if f2 > 0 else None,
                    "compliance_torque": float(dq[2] / w[2]) if w[2] != 0 else None,
                    "final_speed": float(np.hypot(v[end, 0], v[end, 1]))})
        k = end + 1
    return out


def summarize(run: RunData, rc: Recomputation) -> dict[str, Any]:
    """The JSON result: the run's :class:`~contgrasp_ros.launcher.summary.RunSummary` built from the
    recording (simulator status, last rod state, contact and quality; by the launcher's own
    :func:`~contgrasp_ros.launcher.summary.build_summary`) plus the recomputation and recording checks."""
    rod, c, q = run.rod, run.contact, run.quality
    settled_re, settle_re = settle_recomputed(run)
    gaps = step_gaps(run)
    summary = build_summary(
        run.status,
        final=FinalState.of(int(rod.step[-1]), float(rod.t[-1]), rod.s[-1], rod.x[-1], rod.y[-1], rod.theta[-1]),
        final_quality=None if q is None else FinalQuality.of(q.q1[-1], q.q2[-1], q.q3[-1], q.valid[-1], q.contact_length[-1],
                                                                     q.step[-1]),
        contact=contact_stats(None) if c is None else contact_stats(c.s[-1], c.rho[-1], c.delta[-1], c.alpha[-1], c.in_contact[-1], float(c.tol[-1])),
        controller=run.controller_status,
        object_q=None if rod.object is None else rod.object.q[-1],
        object_v=None if rod.object is None else rod.object.v[-1],
    )
    return {
        "path": str(run.path),
        "topics": run.topics,
        **summary.to_dict(),
        "recorded_sim_time_s": float(rod.t[-1] - rod.t[0]),
        "object": object_name(run),
        "object_motion": object_motion(run),
        "settled_recomputed": settled_re,
        "settle_time_recomputed_s": settle_re,
        "max_penetration_recomputed": float(rod.max_penetration.max()) if gaps["contiguous"] and gaps["first_step"] == 0 else None,
        "peak_couple_recomputed": peak_couple_recomputed(run),
        "max_recompute_error": rc.max_error,
        "recompute_errors": rc.errors,
        "recomputed_pairs": {"contact": rc.contact_pairs, "quality": rc.quality_pairs},
        "recompute_mismatches": {"in_contact": rc.in_contact_mismatches, "valid": rc.valid_mismatches},
        "recompute_failures": rc.failures[:20],
        "recompute_parameters": rc.parameters,
        "step_gaps": gaps,
        "messages": {"rod_state": len(rod.step), "contact": 0 if c is None else len(c.step),
                     "quality": 0 if q is None else len(q.step)},
        "recorder": run.recorder,
        "run": run.run_info or None,
        "concurrent_processes": run.concurrent or [],
    }


def _long_rows(t: Array, steps: IntArray, cols: list[Any], extra: Sequence[Any] = ()) -> Iterator[list[Any]]:
    """One row per state and node: t, step, i, the node's values of ``cols``, then ``extra``
    columns (per-node arrays or per-state scalars)."""
    n = cols[0].shape[1]
    for k in range(len(steps)):
        lists = [c[k].tolist() for c in cols]
        more = [e[k].tolist() if np.ndim(e[k]) else [e[k].item()] * n for e in extra]
        tk, sk = float(t[k]), int(steps[k])
        for i in range(n):
            yield [tk, sk, i, *(v[i] for v in lists), *(v[i] for v in more)]


def _write_rows(path: Path, header: list[str], rows: Iterable[list[Any]]) -> int:
    n = 0
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for row in rows:
            w.writerow(row)
            n += 1
    return n


def write_csv(run: RunData, rc: Recomputation, out_dir: str | Path) -> dict[str, dict[str, Any]]:
    """``rod_state.csv`` (t, step, i, s, x, y, theta, radius, vx, vy) and ``contact.csv`` (t, step,
    i, s, rho, alpha, delta, s_o, shadow_x, shadow_y, in_contact, contact_tolerance) in long format,
    one row per recorded state and node; ``quality.csv`` (t, step, q1, q2, q3, contact_length,
    valid, recomputed_q1..3) one row per quality message, the recomputed values empty where the
    rod state of that step was not recorded; for a movable object ``object.csv`` (t, step, dx,
    dy, dpsi, vx, vy, omega, fx, fy, torque) one row per rod state. Floats are written
    round-trip exact."""
    d = Path(out_dir)
    r, c, q = run.rod, run.contact, run.quality
    files: dict[str, dict[str, Any]] = {}
    try:
        d.mkdir(parents=True, exist_ok=True)
        rows = _write_rows(d / "rod_state.csv", ["t", "step", "i", "s", "x", "y", "theta", "radius", "vx", "vy"],
                           _long_rows(r.t, r.step, [r.s, r.x, r.y, r.theta, r.radius, r.vx, r.vy]))
        files["rod_state"] = {"path": str(d / "rod_state.csv"), "rows": rows}
        if c is not None:
            rows = _write_rows(
                d / "contact.csv",
                ["t", "step", "i", "s", "rho", "alpha", "delta", "s_o", "shadow_x", "shadow_y", "in_contact", "contact_tolerance"],
                _long_rows(c.t, c.step, [c.s, c.rho, c.alpha, c.delta, c.s_o, c.shadow_x, c.shadow_y],
                           [c.in_contact.astype(np.int64), c.tol]),
            )
            files["contact"] = {"path": str(d / "contact.csv"), "rows": rows}
        if q is not None:
            again = {int(j): rc.quality[n].tolist() for n, j in enumerate(rc.quality_index)}
            rows = _write_rows(
                d / "quality.csv",
                ["t", "step", "q1", "q2", "q3", "contact_length", "valid", "recomputed_q1", "recomputed_q2", "recomputed_q3"],
                ([float(q.t[j]), int(q.step[j]), float(q.q1[j]), float(q.q2[j]), float(q.q3[j]), float(q.contact_length[j]),
                  int(q.valid[j]), *again.get(j, ["", "", ""])] for j in range(len(q.step))),
            )
            files["quality"] = {"path": str(d / "quality.csv"), "rows": rows}
        if r.object is not None:
            o = r.object
            rows = _write_rows(d / "object.csv", ["t", "step", "dx", "dy", "dpsi", "vx", "vy", "omega", "fx", "fy", "torque"],
                               ([float(r.t[k]), int(r.step[k]), *o.q[k].tolist(), *o.v[k].tolist(), *o.wrench[k].tolist()]
                                for k in range(len(r.step))))
            files["object"] = {"path": str(d / "object.csv"), "rows": rows}
    except OSError as exc:
        raise WriteError(f"cannot write CSV files to {d}: {exc.strerror or exc}") from exc
    return files


def quality_plot_path(path: str | Path) -> Path:
    """Where :func:`write_plots` puts the quality figure: ``FILE`` with ``_quality`` before the suffix."""
    p = Path(path)
    return p.with_name(f"{p.stem}_quality{p.suffix or '.png'}")


def _settle_rule(run: RunData) -> tuple[float, float]:
    """(settle_speed, settle_hold) of the simulator's settle rule, as :func:`recompute_parameters` finds them."""
    par = recompute_parameters(run)
    return float(par["settle_speed"]), float(par["settle_hold"])


def write_plots(run: RunData, rc: Recomputation, path: str | Path, settle_time: float | None = None) -> dict[str, Any]:
    """Two figures: ``path``, the Fig. 4-style figure (:func:`contgrasp_core.figures.run.run_figure`,
    needs the run's parameters and paired rod/contact states), and :func:`quality_plot_path`,
    Q1, Q2, Q3 over sim time as recorded (line) and recomputed from the rod states (crosses)."""
    from contgrasp_core.figures.run import quality_history_figure, run_figure

    out: dict[str, Any] = {"figure": None, "quality": None}
    hist = history(run)
    try:
        if run.params is None:
            out["figure_skipped"] = "the recording holds no run parameters (contgrasp_run metadata)"
        elif not hist:
            out["figure_skipped"] = "no rod state and contact state of the same step were recorded"
        else:
            run_figure({"history": hist}, run.params, str(path))
            out["figure"] = str(path)
        q = run.quality
        if q is None:
            out["quality_skipped"] = f"no {topics.QUALITY} messages were recorded"
            return out
        qpath = quality_plot_path(path)
        quality_history_figure(q.t, (q.q1, q.q2, q.q3), str(qpath), recomputed_t=q.t[rc.quality_index],
                               recomputed=rc.quality, settle_time=settle_time, settle_rule=_settle_rule(run))
        out["quality"] = str(qpath)
    except (OSError, ValueError) as exc:
        if isinstance(exc, ContgraspError):
            raise
        raise output_error(f"the plot {path}", exc) from exc
    return out


def check(result: dict[str, Any]) -> None:
    """:class:`MixedRecordingError` when an analysis (:func:`analyze`'s result) shows two
    processes of one node at once (:func:`concurrent_processes`); :class:`RecomputeMismatchError`
    when it shows a recompute error above :data:`RECOMPUTE_BOUND`, mismatching contact flags or
    validity, or failed recomputations."""
    mixed = result.get("concurrent_processes")
    if mixed:
        pairs = "; ".join(f"{m['node']} from pids {m['pids'][0]} and {m['pids'][1]}" for m in mixed)
        raise MixedRecordingError(f"the recording mixes two graphs' messages: statuses of {pairs} at once (two graphs "
                                  "in one domain and namespace: give each its own --namespace or --domain-id)", result)
    problems = []
    err = result.get("max_recompute_error")
    if err is not None and not err <= RECOMPUTE_BOUND:
        worst = max((k for k, v in result["recompute_errors"].items() if v is not None and not k.endswith("_relative")),
                    key=lambda k: result["recompute_errors"][k])
        problems.append(f"max_recompute_error {err:.3g} > {RECOMPUTE_BOUND:g} (largest: {worst})")
    bad = {k: v for k, v in result.get("recompute_mismatches", {}).items() if v}
    if bad:
        problems.append("mismatches " + ", ".join(f"{k} {v}" for k, v in bad.items()))
    if result.get("recompute_failures"):
        problems.append(f"{len(result['recompute_failures'])} recomputations failed")
    if problems:
        raise RecomputeMismatchError(f"the recording does not recompute: {'; '.join(problems)} "
                                     f"(recompute parameters from {result['recompute_parameters']['source']})", result)


def analyze(
    path: str | Path,
    *,
    csv_dir: str | Path | None = None,
    plot: str | Path | None = None,
    sensor_tolerance: float | None = None,
    quality_tolerance: float | None = None,
) -> dict[str, Any]:
    """Analyse a recording: :func:`load_run`, :func:`recompute`, :func:`summarize`, and with
    ``csv_dir``/``plot`` :func:`write_csv`/:func:`write_plots`. Raises :class:`BagError` /
    :class:`ContgraspError` for bad input."""
    for name, value in (("sensor_tolerance", sensor_tolerance), ("quality_tolerance", quality_tolerance)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value)):
            raise InvalidParameterError(f"{name} must be a finite number, got {value!r}")
    for name, where in (("csv_dir", csv_dir), ("plot", plot)):
        if where is not None and not isinstance(where, str | Path):
            raise InvalidParameterError(f"{name} must be a path, got {where!r}")
    run = load_run(path)
    rc = recompute(run, sensor_tolerance=sensor_tolerance, quality_tolerance=quality_tolerance)
    out = summarize(run, rc)
    if csv_dir is not None:
        out["csv"] = write_csv(run, rc, csv_dir)
    if plot is not None:
        out["plot"] = write_plots(run, rc, plot, out["settle_time_s"])
    return out
