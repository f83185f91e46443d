"""A recorded graph run as numpy arrays (:func:`load_run`), without ROS.

Decodes a launcher's recording (``mcap_ros2``, no message packages): each topic's messages in
the order they were published, the run's parameters and the recorder's record, the last
statuses of the simulator and the controller, and whether two processes published one node's
status at once (:func:`concurrent_processes`). docs/analysis.md.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contgrasp_core.boundary import Boundary
from contgrasp_core.errors import ContgraspError, InvalidParameterError
from contgrasp_core.scenario import PAPER
from contgrasp_ros.bag import BagInputError
from contgrasp_ros.bag.reader import info, iter_decoded, open_recording
from contgrasp_ros.plumbing import topics
from contgrasp_ros.plumbing.convert import (
    ContactArrays,
    ObjectArrays,
    RodArrays,
    boundary_from_msg,
    contact_arrays,
    couple_arrays,
    rod_state_arrays,
    stamp_seconds,
)

__all__ = [
    "RUN_RECORD",
    "RECORDER_RECORD",
    "SIMULATOR",
    "CONTROLLER",
    "node_default",
    "ObjectSeries",
    "RodSeries",
    "ContactSeries",
    "QualitySeries",
    "RunData",
    "concurrent_processes",
    "load_run",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

# topic names as in contgrasp_ros.plumbing.qos (not imported: that module imports rclpy)
RUN_RECORD = "contgrasp_run"  # = contgrasp_ros.bag.writer.RUN_RECORD
RECORDER_RECORD = "contgrasp_recorder"  # = contgrasp_ros.bag.writer.RECORDER_RECORD
SIMULATOR = "rod_simulator"
CONTROLLER = "grasp_controller"


def node_default(node: str, key: str) -> Any:
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
    transitions: dict[int, bool] | None = None  # whether that couple's law was still in transition
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
    couples, transitions = _couples(by_topic[topics.COUPLE]) if counts.get(name[topics.COUPLE]) else (None, None)
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
        couples=couples,
        transitions=transitions,
        recorder=recorder,
        repeated_states=repeated,
        concurrent=concurrent_processes(spans),
    )


def _couples(msgs: list[Any]) -> tuple[dict[int, Any], dict[int, bool]]:
    """``couples`` and ``transitions`` of :class:`RunData`: the first usable couple answering each
    step (a re-sent state is answered twice; a malformed message is left out, as the simulator
    leaves it out) and its law's ``transition`` flag."""
    couples: dict[int, Any] = {}
    transitions: dict[int, bool] = {}
    for msg in msgs:
        try:
            step, _, couple, transition = couple_arrays(msg)
        except ContgraspError:
            continue
        if step not in couples:
            couples[step], transitions[step] = couple, transition
    return couples, transitions
