"""Offline analysis of a recorded graph run (``contgrasp analyze BAG``), without ROS.

:func:`load_run` decodes a launcher's recording (``mcap_ros2``, no message packages) into numpy
arrays; :func:`recompute` repeats the sensing (paper eqs. (4), (5), Definition 1) and the grasp
quality (Sec. IV) from the recorded rod states with the functions the nodes call, so a genuine
recording agrees with its recorded topics to rounding; :func:`summarize` builds the launcher's
summary plus the recomputation errors; :func:`write_csv` and :func:`write_plots` export the run.
Decimated recordings are paired by ``step``. Nothing here imports rclpy. docs/analysis.md.
"""

from __future__ import annotations

import csv
import itertools
import json
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.boundary import Boundary
from contgrasp_core.contact import sense
from contgrasp_core.errors import ContgraspError, InvalidParameterError, RunFailure, WriteError, output_error
from contgrasp_core.objects import OUTLINE, ROD_SCALE, SHAPES, ObjectSpec, outline_text
from contgrasp_core.rod.closed_loop import SettleDetector
from contgrasp_ros.plumbing import topics
from contgrasp_ros.bag import BagInputError
from contgrasp_ros.bag.reader import info, iter_decoded, open_recording
from contgrasp_core.scenario import PAPER, rod_from_parameters
from contgrasp_ros.plumbing.convert import (
    ContactArrays,
    HeldShape,
    ObjectArrays,
    RodArrays,
    boundary_from_msg,
    contact_arrays,
    couple_arrays,
    rod_state_arrays,
    stamp_seconds,
)
from contgrasp_ros.plumbing.evaluate import contact_quality
from contgrasp_ros.launcher.summary import FinalQuality, FinalState, build_summary, contact_stats

__all__ = [
    "RodSeries",
    "ObjectSeries",
    "ContactSeries",
    "QualitySeries",
    "RunData",
    "Recomputation",
    "load_run",
    "recompute",
    "summarize",
    "object_name",
    "object_motion",
    "write_csv",
    "write_plots",
    "analyze",
    "check",
    "RecomputeMismatchError",
    "MixedRecordingError",
    "concurrent_processes",
    "RECOMPUTE_BOUND",
]

RECOMPUTE_BOUND = 1e-9
"""Largest recompute error of a genuine recording (in practice it is 0: the same functions on
the same float64 arrays)."""


class RecomputeMismatchError(RunFailure):
    """The recording does not recompute: an error above :data:`RECOMPUTE_BOUND`, contact flags or
    quality validity that differ, or steps whose recomputation failed. ``result`` is the
    analysis (``contgrasp analyze`` prints it, then the one error line, and exits 1)."""

    def __init__(self, message: str, result: dict[str, Any]) -> None:
        super().__init__(message)
        self.result = result


class MixedRecordingError(RunFailure):
    """The recording holds two graphs' messages: one node's status came from two processes at
    once (another graph ran in the same domain and namespace). ``result`` as in
    :class:`RecomputeMismatchError`."""

    def __init__(self, message: str, result: dict[str, Any]) -> None:
        super().__init__(message)
        self.result = result

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

# topic names as in contgrasp_ros.plumbing.qos (not imported: that module imports rclpy)
RUN_RECORD = "contgrasp_run"  # = contgrasp_ros.bag.writer.RUN_RECORD
RECORDER_RECORD = "contgrasp_recorder"  # = contgrasp_ros.bag.writer.RECORDER_RECORD
SIMULATOR = "rod_simulator"
CONTROLLER = "grasp_controller"



def _default(node: str, key: str) -> Any:
    """A node's default (the scenario model's, as the nodes declare it) for a parameter a run omits."""
    return PAPER.node_parameters(node)[key]


@dataclass
class ObjectSeries:
    """A movable object in the recorded rod states (K rows): its centroid at the start pose
    (K, 2), displacement ``q``, velocity ``v`` and the wrench held on it (K, 3)."""

    centroid: Array
    q: Array
    v: Array
    wrench: Array


@dataclass
class RodSeries:
    """Recorded rod states: ``step``/``t`` (K,), per-node arrays (K, n), ``max_penetration`` (K,),
    the movable object's ``object`` (None: fixed)."""

    step: IntArray
    t: Array
    s: Array
    x: Array
    y: Array
    theta: Array
    radius: Array
    vx: Array
    vy: Array
    max_penetration: Array
    object: ObjectSeries | None = None

    def arrays(self, k: int) -> RodArrays:
        """The k-th state as the sensor node reads it (:func:`contgrasp_ros.plumbing.convert.rod_state_arrays`)."""
        o = self.object
        body = None if o is None else ObjectArrays(o.centroid[k], o.q[k], o.v[k], o.wrench[k])
        return RodArrays(int(self.step[k]), float(self.t[k]), self.s[k], self.x[k], self.y[k], self.theta[k],
                         np.zeros(0), self.radius[k], body)

    @property
    def max_speed(self) -> Array:
        """Largest node speed hypot(vx, vy) of each state (what the settle rule watches)."""
        return np.hypot(self.vx, self.vy).max(axis=1)


@dataclass
class ContactSeries:
    """Recorded contact states (K, n) with their ``step``/``t`` and tolerance (K,)."""

    step: IntArray
    t: Array
    s: Array
    rho: Array
    alpha: Array
    delta: Array
    s_o: Array
    shadow_x: Array
    shadow_y: Array
    in_contact: NDArray[np.bool_]
    tol: Array


@dataclass
class QualitySeries:
    """Recorded grasp quality: ``w`` (K, 9) row-major, Q1..Q3, contact length, tolerance, valid."""

    step: IntArray
    t: Array
    w: Array
    q1: Array
    q2: Array
    q3: Array
    contact_length: Array
    contact_tolerance: Array
    valid: NDArray[np.bool_]


@dataclass
class RunData:
    """Everything :func:`summarize` needs from a recording, as arrays."""

    path: Path
    topics: list[dict[str, Any]]
    rod: RodSeries
    contact: ContactSeries | None
    quality: QualitySeries | None
    boundary: Boundary
    params: dict[str, dict[str, Any]] | None
    run_info: dict[str, Any]
    status: dict[str, str]
    controller_status: dict[str, str]  # (the controller's last /diagnostics values: law, law_phase)
    couples: dict[int, Any] | None = None  # the recorded couple answering each step (convert.couple_arrays)
    recorder: dict[str, Any] | None = None
    repeated_states: int = 0  # rod states published again (a re-send), each kept once
    concurrent: list[dict[str, Any]] | None = None  # (concurrent_processes of the statuses)


def _repeat(last: Any, msg: Any) -> bool:
    """Whether a rod or contact state is ``last`` published again: the simulator sends a state
    the loop waits on again (a peer joined after it went out: docs/ros.md, "Why step 0 is never
    lost") and the sensor its answer to it; same step, same stamp."""
    return bool(last.step == msg.step and last.header.stamp.sec == msg.header.stamp.sec
                and last.header.stamp.nanosec == msg.header.stamp.nanosec)


def concurrent_processes(spans: dict[str, dict[int, tuple[int, int]]]) -> list[dict[str, Any]]:
    """The statuses published by two processes at once, from each status name's processes and
    the first and last publish time of each (``spans[name][pid] = (first_ns, last_ns)``): one
    entry ``{"node": name, "pids": [a, b]}`` per overlapping pair of a name. A restarted node's
    processes follow one another (the old one's last status comes before the new one's first);
    two graphs in one domain and namespace publish side by side."""
    out = []
    for name, by_pid in sorted(spans.items()):
        ordered = sorted(by_pid.items(), key=lambda kv: kv[1])
        for (pid_a, (_, last_a)), (pid_b, (first_b, _)) in itertools.pairwise(ordered):
            if first_b <= last_a:
                out.append({"node": name, "pids": [pid_a, pid_b]})
    return out


def _stack(rows: list[Any], what: str) -> Array:
    try:
        return np.stack([np.asarray(r, dtype=float) for r in rows])
    except ValueError as exc:
        raise BagInputError(f"{what}: the recorded messages differ in their number of nodes ({exc})") from exc


def _json_values(record: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, text in record.items():
        try:
            out[key] = json.loads(text)
        except (TypeError, ValueError):
            out[key] = text
    return out


def _rod_series(msgs: list[Any]) -> RodSeries:
    cols: dict[str, list[Any]] = {k: [] for k in ("s", "x", "y", "theta", "radius", "vx", "vy")}
    steps, ts, pens = [], [], []
    bodies: list[ObjectArrays | None] = []
    for i, msg in enumerate(msgs):
        try:
            a = rod_state_arrays(msg)
            vx, vy = np.asarray(msg.vx, dtype=float), np.asarray(msg.vy, dtype=float)
            if vx.shape != a.s.shape or vy.shape != a.s.shape or not (np.all(np.isfinite(vx)) and np.all(np.isfinite(vy))):
                raise InvalidParameterError("RodState: 'vx'/'vy' must be finite with one value per node")
        except ContgraspError as exc:
            raise BagInputError(f"{topics.ROD_STATE} message #{i} (step {getattr(msg, 'step', '?')}): {exc}") from exc
        steps.append(a.step)
        ts.append(a.t)
        pens.append(float(msg.max_penetration))
        bodies.append(a.object)
        for key, val in (("s", a.s), ("x", a.x), ("y", a.y), ("theta", a.theta), ("radius", a.radius), ("vx", vx), ("vy", vy)):
            cols[key].append(val)
    st = {k: _stack(v, topics.ROD_STATE) for k, v in cols.items()}
    return RodSeries(np.asarray(steps, dtype=np.int64), np.asarray(ts), max_penetration=np.asarray(pens),
                     object=_object_series(bodies), **st)


def _object_series(bodies: list[ObjectArrays | None]) -> ObjectSeries | None:
    moving = [b for b in bodies if b is not None]
    if not moving:
        return None
    if len(moving) != len(bodies):
        raise BagInputError(f"{topics.ROD_STATE}: {len(moving)} of {len(bodies)} rod states carry the object's motion "
                            "(a run's object is either fixed or movable)")
    return ObjectSeries(*(np.stack([getattr(b, k) for b in moving]) for k in ("centroid", "q", "v", "wrench")))


def _contact_series(msgs: list[Any]) -> ContactSeries | None:
    if not msgs:
        return None
    rows: list[ContactArrays] = []
    for i, msg in enumerate(msgs):
        try:
            rows.append(contact_arrays(msg))
        except ContgraspError as exc:
            raise BagInputError(f"{topics.CONTACT} message #{i} (step {getattr(msg, 'step', '?')}): {exc}") from exc
    s, rho, alpha, delta, s_o = (_stack([getattr(c, k) for c in rows], topics.CONTACT) for k in ("s", "rho", "alpha", "delta", "s_o"))
    return ContactSeries(
        np.asarray([c.step for c in rows], dtype=np.int64),
        np.asarray([c.t for c in rows]),
        s, rho, alpha, delta, s_o,
        _stack([c.shadow[:, 0] for c in rows], topics.CONTACT),
        _stack([c.shadow[:, 1] for c in rows], topics.CONTACT),
        np.stack([c.in_contact for c in rows]),
        np.asarray([c.tol for c in rows]),
    )


def _quality_series(msgs: list[Any]) -> QualitySeries | None:
    if not msgs:
        return None
    w = [np.asarray(m.w, dtype=float) for m in msgs]
    if any(v.shape != (9,) for v in w):
        raise BagInputError(f"{topics.QUALITY}: a message's W does not have 9 entries")
    q1, q2, q3, length, tol = (
        np.asarray([float(getattr(m, k)) for m in msgs]) for k in ("q1", "q2", "q3", "contact_length", "contact_tolerance")
    )
    return QualitySeries(
        np.asarray([int(m.step) for m in msgs], dtype=np.int64),
        np.asarray([stamp_seconds(m.header) for m in msgs]),
        np.stack(w),
        q1, q2, q3, length, tol,
        np.asarray([bool(m.valid) for m in msgs]),
    )


def load_run(path: str | Path) -> RunData:
    """Decode a recording (bag folder or ``.mcap``) into arrays, each topic's messages in the
    order they were published; :class:`BagError` for a missing/corrupt file or one without rod
    states or object boundary."""
    rec = open_recording(path)
    meta = info(rec)
    recorded = [{"name": t["name"], "type": t["type"], "count": t["count"]} for t in meta["topics"]]
    counts = {t["name"]: t["count"] for t in recorded}
    ns = topics.recorded_namespace(counts)  # (a graph run under a namespace: its topics)
    name = {t: topics.resolve(t, ns) for t in (topics.ROD_STATE, topics.CONTACT, topics.QUALITY, topics.OBJECT, topics.COUPLE)}
    if not counts.get(name[topics.ROD_STATE]):
        have = ", ".join(f"{n} ({c})" for n, c in counts.items()) or "none"
        raise BagInputError(f"{path}: no {name[topics.ROD_STATE]} messages to analyse (recorded topics: {have})")
    if not counts.get(name[topics.OBJECT]):
        raise BagInputError(f"{path}: no {name[topics.OBJECT]} message (the object boundary is needed to recompute contact "
                            "and quality)")
    records = rec.metadata_records()
    run_info = _json_values(records.get(RUN_RECORD, {}))
    params = run_info.pop("params", None)
    if params is not None and not (isinstance(params, dict) and all(isinstance(v, dict) for v in params.values())):
        raise BagInputError(f"{path}: the {RUN_RECORD!r} metadata record's params are not per-node parameter mappings")
    recorder = _json_values(records[RECORDER_RECORD]) if RECORDER_RECORD in records else None

    by_topic: dict[str, list[Any]] = {topics.ROD_STATE: [], topics.CONTACT: [], topics.QUALITY: [], topics.OBJECT: [],
                                      topics.COUPLE: []}
    status: dict[str, str] = {}
    controller: dict[str, str] = {}
    spans: dict[str, dict[int, tuple[int, int]]] = {}  # (status name -> pid -> first, last publish time)
    repeated = 0
    # in the order they were published, not by log time: a simulated-time log time is the header
    # stamp, and a late message stamped t = 0 (unset) is logged at the recorder's clock instead
    relative = {v: k for k, v in name.items()}
    simulator = topics.status_name(SIMULATOR, ns)
    for raw, msg in sorted(iter_decoded(rec, [*relative, topics.DIAGNOSTICS]), key=lambda rm: rm[0].publish_time_ns):
        if raw.topic != topics.DIAGNOSTICS:
            topic = relative[raw.topic]
            kept = by_topic[topic]
            if topic in (topics.ROD_STATE, topics.CONTACT) and kept and _repeat(kept[-1], msg):
                if topic == topics.ROD_STATE:
                    repeated += 1
                continue
            kept.append(msg)
            continue
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            pid, now = values.get("pid", ""), raw.publish_time_ns
            if pid.isdigit():  # (a recording from before statuses carried it has none)
                first, _ = spans.setdefault(st.name, {}).get(int(pid), (now, now))
                spans[st.name][int(pid)] = (first, now)
            if st.name == simulator:
                status = values
            elif st.name == topics.status_name(CONTROLLER, ns):
                controller = values
    try:
        boundary = boundary_from_msg(by_topic[topics.OBJECT][-1])
    except ContgraspError as exc:
        raise BagInputError(f"{path}: the recorded object boundary is unusable: {exc}") from exc
    return RunData(
        path=Path(path),
        topics=recorded,
        rod=_rod_series(by_topic[topics.ROD_STATE]),
        contact=_contact_series(by_topic[topics.CONTACT]),
        quality=_quality_series(by_topic[topics.QUALITY]),
        boundary=boundary,
        params=params,
        run_info=run_info,
        status=status,
        controller_status=controller,
        couples=_couples(by_topic[topics.COUPLE]) if counts.get(name[topics.COUPLE]) else None,
        recorder=recorder,
        repeated_states=repeated,
        concurrent=concurrent_processes(spans),
    )


def _couples(msgs: list[Any]) -> dict[int, Any]:
    """The first usable couple answering each step (a re-sent state is answered twice; a
    malformed message is left out, as the simulator leaves it out)."""
    out: dict[int, Any] = {}
    for msg in msgs:
        try:
            step, _, couple, _ = couple_arrays(msg)
        except ContgraspError:
            continue
        out.setdefault(step, couple)
    return out


def peak_couple_recomputed(run: RunData) -> float | None:
    """The largest |u| the recorded couples applied (N m), each at the state it answers, after
    the muscles' bound (:func:`contgrasp_core.rod.muscle.saturate`): the couple itself, or a
    hold's at the recorded state's angles. None without recorded couples, or when a hold
    answers a state that was not recorded (decimated)."""
    from contgrasp_core.rod.chain import element_angles
    from contgrasp_core.rod.muscle import saturate

    if not run.couples:
        return None
    model = rod_from_parameters({**PAPER.node_parameters(SIMULATOR), **(run.params or {}).get(SIMULATOR, {})})
    row = {int(k): i for i, k in enumerate(run.rod.step)}
    peak = 0.0
    for step, couple in run.couples.items():
        if isinstance(couple, HeldShape):
            if step not in row:
                return None
            hold = couple.hold(model)
            u = hold.couple + hold.couple_and_jacobian(element_angles(run.rod.theta[row[step]]), jacobian=False)[0]
        else:
            u = np.asarray(getattr(couple, "u", couple), dtype=float)
        peak = max(peak, float(np.abs(saturate(model, u)).max()))
    return peak


@dataclass
class Recomputation:
    """Recomputed contact and quality and their differences from the recorded topics."""

    parameters: dict[str, Any]
    errors: dict[str, float | None]
    contact_pairs: int
    quality_pairs: int
    in_contact_mismatches: int
    valid_mismatches: int
    failures: list[str]
    quality_index: IntArray  # indices into the QualitySeries that were recomputed
    quality: Array  # (len(quality_index), 3): recomputed Q1, Q2, Q3

    @property
    def max_error(self) -> float | None:
        vals = [v for k, v in self.errors.items() if v is not None and not k.endswith("_relative")]
        return max(vals) if vals else None


def _param(params: dict[str, dict[str, Any]] | None, node: str, key: str, default: float) -> float:
    if params is None:
        return default
    return float(params.get(node, {}).get(key, default))


def recompute_parameters(run: RunData) -> dict[str, Any]:
    """Sensor/quality tolerances and wrench reference the nodes ran with: the run's parameters
    (MCAP metadata) or, without them, what the recorded messages carry and the node defaults."""
    settle = {k: _param(run.params, SIMULATOR, k, _default(SIMULATOR, k))
              for k in ("settle_speed", "settle_hold", "min_time")}  # the simulator's settle rule
    if run.params is not None:
        return {
            **settle,
            "source": "run parameters",
            "sensor_contact_tolerance": _param(run.params, "boundary_sensor", "contact_tolerance", _default("boundary_sensor", "contact_tolerance")),
            # the quality node uses the contact states' own tolerance (-1); recordings made before
            # the run had one contact set carry the quality node's own
            "quality_contact_tolerance": _param(run.params, "grasp_quality", "contact_tolerance", -1.0),
            "reference": [_param(run.params, "grasp_quality", k, _default("grasp_quality", k)) for k in ("reference_x", "reference_y")],
        }
    return {
        **settle,
        "source": "recorded messages and node defaults (no run parameters in the recording)",
        "sensor_contact_tolerance": float(run.contact.tol[0]) if run.contact is not None else _default("boundary_sensor", "contact_tolerance"),
        "quality_contact_tolerance": float(run.quality.contact_tolerance[0]) if run.quality is not None else -1.0,
        "reference": [_default("grasp_quality", "reference_x"), _default("grasp_quality", "reference_y")],
    }


def _to_contact_arrays(step: int, t: float, state: Any) -> ContactArrays:
    """What the quality node reads from the sensor's message of ``state`` (float64 round trip)."""
    return ContactArrays(step, t, state.s, state.rho, state.alpha, state.delta, state.s_o, state.foot,
                         np.asarray(state.in_contact, dtype=bool), float(state.tol))


_CONTACT_KEYS = ("rho", "alpha", "delta", "s_o", "shadow")
_QUALITY_KEYS = ("W", "Q1", "Q2", "Q3", "contact_length")


def recompute(
    run: RunData,
    *,
    sensor_tolerance: float | None = None,
    quality_tolerance: float | None = None,
    reference: tuple[float, float] | None = None,
) -> Recomputation:
    """Recompute the contact state of every recorded rod state that has a recorded contact state
    of the same step (:func:`contgrasp_core.contact.sense`, as the boundary sensor; eqs.
    (4) and (5)), and the quality of every recorded quality step whose rod state was recorded
    (rod state -> sensing -> :func:`~contgrasp_ros.plumbing.evaluate.contact_quality`, Sec. IV,
    W = int_S G G^T ds); return the largest absolute differences per quantity.

    The keyword arguments override the run's parameters (e.g. to check that a wrong tolerance
    is noticed); ``quality_tolerance < 0`` means the sensor's tolerance, as in the node.
    """
    par = recompute_parameters(run)
    if sensor_tolerance is not None:
        par["sensor_contact_tolerance"] = float(sensor_tolerance)
    if quality_tolerance is not None:
        par["quality_contact_tolerance"] = float(quality_tolerance)
    if reference is not None:
        par["reference"] = [float(reference[0]), float(reference[1])]
    s_tol, q_tol, ref = par["sensor_contact_tolerance"], par["quality_contact_tolerance"], tuple(par["reference"])
    rod_at = {int(k): i for i, k in enumerate(run.rod.step)}
    err: dict[str, float] = {}
    failures: list[str] = []
    sensed: dict[int, Any] = {}

    def sensed_state(i: int) -> Any:
        if i not in sensed:
            rod = run.rod.arrays(i)
            sensed[i] = sense(rod.sensed_shape, run.boundary, rod.radius, tol=s_tol)
        return sensed[i]

    def bump(key: str, value: float) -> None:
        err[key] = max(err.get(key, 0.0), float(value))

    n_contact = in_contact_bad = 0
    c = run.contact
    if c is not None:
        for j, k in enumerate(c.step):
            i = rod_at.get(int(k))
            if i is None:
                continue
            try:
                st = sensed_state(i)
            except ContgraspError as exc:
                failures.append(f"contact at step {k}: {exc}")
                continue
            n_contact += 1
            if st.rho.shape != c.rho[j].shape:
                failures.append(f"contact at step {k}: {len(st.rho)} nodes recomputed, {len(c.rho[j])} recorded")
                continue
            bump("rho", np.max(np.abs(st.rho - c.rho[j])))
            bump("alpha", np.max(np.abs(st.alpha - c.alpha[j])))
            bump("delta", np.max(np.abs(st.delta - c.delta[j])))
            bump("s_o", np.max(np.abs(st.s_o - c.s_o[j])))
            bump("shadow", max(np.max(np.abs(st.foot[:, 0] - c.shadow_x[j])), np.max(np.abs(st.foot[:, 1] - c.shadow_y[j]))))
            in_contact_bad += int(np.count_nonzero(st.in_contact != c.in_contact[j]))

    q_idx: list[int] = []
    q_vals: list[tuple[float, float, float]] = []
    valid_bad = 0
    q = run.quality
    if q is not None:
        for j, k in enumerate(q.step):
            i = rod_at.get(int(k))
            if i is None:
                continue
            try:
                st = sensed_state(i)
                qq = contact_quality(_to_contact_arrays(int(k), float(run.rod.t[i]), st), run.boundary, q_tol, ref)
            except ContgraspError as exc:
                failures.append(f"quality at step {k}: {exc}")
                continue
            q_idx.append(j)
            q_vals.append((qq.Q1, qq.Q2, qq.Q3))
            bump("W", np.max(np.abs(np.asarray(qq.W, dtype=float).ravel() - q.w[j])))
            bump("Q1", abs(qq.Q1 - q.q1[j]))
            bump("Q2", abs(qq.Q2 - q.q2[j]))
            bump("Q3", abs(qq.Q3 - q.q3[j]))
            bump("contact_length", abs(qq.contact_length - q.contact_length[j]))
            scale = max(abs(q.q2[j]), abs(qq.Q2))
            bump("Q2_relative", abs(qq.Q2 - q.q2[j]) / scale if scale > 0 else 0.0)
            valid_bad += int(bool(qq.has_contact) != bool(q.valid[j]))

    errors: dict[str, float | None] = {k: err.get(k) for k in (*_CONTACT_KEYS, *_QUALITY_KEYS, "Q2_relative")}
    return Recomputation(
        parameters=par,
        errors=errors,
        contact_pairs=n_contact,
        quality_pairs=len(q_idx),
        in_contact_mismatches=in_contact_bad,
        valid_mismatches=valid_bad,
        failures=failures,
        quality_index=np.asarray(q_idx, dtype=np.int64),
        quality=np.asarray(q_vals, dtype=float).reshape(-1, 3),
    )


def step_gaps(run: RunData) -> dict[str, Any]:
    """Whether the recorded rod states are every step (a decimated recording is not)."""
    steps = run.rod.step
    d = np.diff(steps)
    return {
        "contiguous": bool(np.all(d == 1)),
        "first_step": int(steps[0]),
        "last_step": int(steps[-1]),
        "rod_states": len(steps),
        "missing_steps": max(int(steps[-1] - steps[0] + 1) - len(np.unique(steps)), 0),
        "max_step_gap": int(d.max()) if len(d) else 0,
        "monotonic": bool(np.all(d > 0)),
        "repeated_states": run.repeated_states,
    }


STAMP_RESOLUTION_S = 1e-9
"""A header stamp's resolution (builtin_interfaces/Time: integer nanoseconds)."""


def settle_recomputed(run: RunData) -> tuple[bool | None, float | None]:
    """(settled, settle time) by the simulator's rule fed every recorded state from step 0 at its
    stamp, the simulated time rounded to ns (the simulator's own float times reach /diagnostics
    only a few times per second): the rule's hold and minimum time are taken 1 ns short, so a
    run the simulator judged settled at the last step is so judged again, and the settle time
    agrees with the simulator's to 1 ns; the rule's parameters as :func:`recompute_parameters`
    finds them (the run's, else the node defaults: a run started by hand records none);
    (None, None) when the rod states are not complete."""
    gaps = step_gaps(run)
    if not gaps["contiguous"] or gaps["first_step"] != 0:
        return None, None
    par = recompute_parameters(run)
    speed, hold, min_time = par["settle_speed"], par["settle_hold"], par["min_time"]
    det = SettleDetector(speed, hold - STAMP_RESOLUTION_S, min_time - STAMP_RESOLUTION_S)
    for t, v in zip(run.rod.t, run.rod.max_speed, strict=True):
        det.update(float(t), float(v))
    return det.settled, det.settle_time


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
        text, outline = str(sim.get("object", _default(SIMULATOR, "object"))), str(sim.get("object_outline", ""))
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
