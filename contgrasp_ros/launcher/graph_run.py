"""Drive one run of the graph and summarise it from what travelled over the topics.

The :class:`Monitor` node (in the launcher's process) subscribes to the rod state, contact,
quality and the simulator's diagnostics; it waits until every node is up and the topics are
matched, resumes the paused simulator through its ``~/pause`` service (std_srvs/SetBool) and
then waits for the simulator to report ``finished`` (or ``failed``) on ``/diagnostics``.
With recording on, the ``mcap_recorder`` starts first, the simulator is resumed only once the
recorder subscribes to every stream, and it is stopped last, after the other nodes, so the
recording holds the whole run; the summary's ``bag`` entry is read back from the finished file.
What to do when (resume, restart a dead node, go on without it, time out) is decided by
:class:`contgrasp_ros.launcher.supervision.Supervisor`; ``_drive`` feeds it what rclpy and the process
group show (once per supervisor's spin period, and at once when the simulator's state
changes) and carries out its actions. The summary is :class:`contgrasp_ros.launcher.summary.RunSummary`.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Container, Sequence
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from std_srvs.srv import SetBool

from contgrasp_core.errors import ContgraspError, RunFailure, exit_code
from contgrasp_msgs.msg import ContactState, GraspQuality, RodState
from contgrasp_ros.plumbing import qos, topics
from contgrasp_ros.nodes.container import node_class
from contgrasp_ros.plumbing.convert import stamp_seconds
from contgrasp_ros.launcher.discovery import discovery_profile_set, use_discovery_profile
from contgrasp_ros.launcher.events import EventSink
from contgrasp_ros.launcher.graph import LOOP as NODES
from contgrasp_ros.launcher.graph import processes as graph_processes
from contgrasp_ros.launcher.graph import parameter_file, recorder_params
from contgrasp_ros.plumbing.faults import DropCounter
from contgrasp_ros.plumbing.runtime import GuardedSpin, join_signal_thread, make_executor
from contgrasp_ros.launcher.supervision import (
    RECORDER,
    Exit,
    Finish,
    Log,
    Notify,
    Observation,
    Phase,
    Restart,
    Resume,
    SetMinSubscribers,
    Supervisor,
    UNRECORDED_MIN_SUBSCRIBERS,
    Unrecorded,
)
from contgrasp_ros.launcher.summary import FinalQuality, FinalState, RunSummary, build_summary, contact_stats

__all__ = ["Monitor", "run_graph"]

RECORDED_STREAMS = (topics.OBJECT, topics.ROD_STATE, topics.CONTACT, topics.COUPLE, topics.QUALITY, topics.CLOCK)
OBJECT_STREAMS = (topics.OBJECT_POSE, topics.OBJECT_TWIST)  # (published when the object moves)
PAIRING_WINDOW = 8  # sampled rod states kept for the contact samples of their steps (each stream in order)


class Monitor(Node):
    """Observes the run: last rod state, contact and quality, a history, the simulator status."""

    def __init__(self, history_period: float | None = 0.01, recording: bool = False,
                 recorded_streams: tuple[str, ...] = RECORDED_STREAMS,
                 own_pids: Callable[[], Container[int]] | None = None, **kw: Any) -> None:
        super().__init__("contgrasp_monitor", **kw)
        self.recording = recording
        # the processes of this run (None: any): a status of one of the graph's nodes from another
        # process is another graph's, in the same domain and namespace (``foreign``: node, pid)
        self._own_pids = own_pids
        self.foreign: tuple[str, int] | None = None
        self.recorded_streams = recorded_streams
        self.rod: RodState | None = None
        self.contact: ContactState | None = None
        self.quality: GraspQuality | None = None
        self.status: dict[str, str] = {}
        self.controller_status: dict[str, str] = {}
        self.state_changed = False  # the simulator's state changed since the driver looked (see _drive)
        self.history: list[dict[str, Any]] = []
        self._period = history_period
        self._next_t = 0.0
        self._rods: dict[int, RodState] = {}  # the latest sampled rod states by step
        self._waiting: ContactState | None = None  # a contact sample whose rod state has not come yet
        # the sampled streams (the first and the final state among them): a per-step reader would
        # cost the loop a wake-up every step
        self.create_subscription(RodState, topics.ROD_STATE_SAMPLED, self._on_rod, qos.STREAM)
        self.create_subscription(ContactState, topics.CONTACT_SAMPLED, self._on_contact, qos.STREAM)
        self.create_subscription(GraspQuality, topics.QUALITY, self._on_quality, qos.STREAM)
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diag, qos.STREAM)
        self.pause = self.create_client(SetBool, "rod_simulator/pause")
        self.sim_params = AsyncParameterClient(self, "rod_simulator")
        self._statuses = {topics.status_name(name, self.get_namespace()): name for name in (*NODES, RECORDER)}
        self.drops = DropCounter(self)  # (only rclpy take failures: see GuardedSpin)

    def _on_rod(self, msg: RodState) -> None:
        self.rod = msg
        self._rods[msg.step] = msg
        while len(self._rods) > PAIRING_WINDOW:
            del self._rods[min(self._rods)]
        if self._waiting is not None and self._waiting.step == msg.step:
            contact, self._waiting = self._waiting, None
            self._record(msg, contact)

    def _on_contact(self, msg: ContactState) -> None:
        """The latest contact; every ``history_period`` one into the history, with the rod state of
        its step, whichever of the two streams brought its message first."""
        self.contact = msg
        if self._period is None:  # no figure wanted: keep no history (it grows with simulated time)
            return
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if t + 1e-12 >= self._next_t:
            self._next_t = t + self._period
            rod = self._rods.get(msg.step)
            if rod is None:
                self._waiting = msg  # (its rod state is still on the way)
            else:
                self._record(rod, msg)

    def _record(self, rod: RodState, contact: ContactState) -> None:
        self.history.append(
            {
                "t": contact.header.stamp.sec + 1e-9 * contact.header.stamp.nanosec,
                "x": list(rod.x),
                "y": list(rod.y),
                "theta": list(rod.theta),
                "radius": list(rod.radius),
                "s": list(contact.s),
                "rho": list(contact.rho),
                "alpha": list(contact.alpha),
                "object_q": list(rod.object_q),
                "object_centroid": list(rod.object_centroid),
            }
        )

    def _on_quality(self, msg: GraspQuality) -> None:
        self.quality = msg

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            node = self._statuses.get(st.name)
            if node is None:
                continue
            values = {kv.key: kv.value for kv in st.values}
            pid = values.get("pid", "")
            if self._own_pids is not None and pid.isdigit() and int(pid) not in self._own_pids():
                self.foreign = (node, int(pid))
            elif node == "rod_simulator":
                state = self.status.get("state")
                self.status = values
                self.state_changed = self.state_changed or self.status.get("state") != state
            elif node == "grasp_controller":
                self.controller_status = values

    def connected(self) -> bool:
        """Every node of the monitor's namespace is up and each stream has its publisher and subscribers matched."""
        ns = self.get_namespace()
        names = {name for name, node_ns in self.get_node_names_and_namespaces() if node_ns == ns}
        if not set(NODES) <= names or not self.pause.service_is_ready():
            return False
        if self.recording and not all(
            any(i.node_name == RECORDER and i.node_namespace == ns for i in self.get_subscriptions_info_by_topic(t)) for t in self.recorded_streams
        ):
            return False
        return (
            self.count_subscribers(topics.ROD_STATE) >= 1
            and self.count_subscribers(topics.ROD_STATE_SAMPLED) >= 2
            and self.count_publishers(topics.CONTACT) >= 1
            and self.count_subscribers(topics.CONTACT) >= 1
            and self.count_publishers(topics.CONTACT_SAMPLED) >= 1
            and self.count_subscribers(topics.CONTACT_SAMPLED) >= 2
            and self.count_publishers(topics.COUPLE) >= 1
            and self.count_subscribers(topics.COUPLE) >= 1
            and self.count_publishers(topics.QUALITY) >= 1
        )


SUPERVISED = {"use_sim_time": True, "on_finish": "supervised"}
"""What the launcher sets on every node it starts: simulated time, and no "staying up" hint when
the run is over (the launcher stops its nodes itself)."""


def _overrides(values: dict[str, Any]) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in values.items()]


def _summary(mon: Monitor, loop_wall_time_s: float | None = None, wall_time_s: float | None = None) -> RunSummary:
    """The run's :class:`~contgrasp_ros.launcher.summary.RunSummary` from what the monitor received."""
    rod, q, c = mon.rod, mon.quality, mon.contact
    return build_summary(
        mon.status,
        final=None if rod is None else FinalState.of(rod.step, stamp_seconds(rod.header), rod.s, rod.x, rod.y, rod.theta),
        final_quality=None if q is None else FinalQuality.of(q.q1, q.q2, q.q3, q.valid, q.contact_length, q.step),
        contact=contact_stats(None) if c is None else contact_stats(c.s, c.rho, c.delta, c.alpha, c.in_contact, c.contact_tolerance),
        controller=mon.controller_status,
        object_q=None if rod is None else rod.object_q,
        object_v=None if rod is None else rod.object_v,
        wall_time_s=wall_time_s,
        loop_wall_time_s=loop_wall_time_s,
    )


def _observe(mon: Monitor, sup: Supervisor, group: Any, resume_fut: Any, params_result: bool | None) -> Observation:
    """What the supervisor decides on: the process group and the graph as the monitor sees them."""
    return Observation(
        now=time.monotonic(),
        exited=tuple(Exit(c.name, c.proc.pid, c.proc.returncode) for c in group.exited()) if group is not None else (),
        connected=sup.phase is Phase.CONNECTING and mon.connected(),
        simulator_state=mon.status.get("state"),
        simulator_message=mon.status.get("message", ""),
        pause_ready=mon.pause.service_is_ready(),
        resume_answered=resume_fut is not None and resume_fut.done(),
        params_ready=mon.sim_params.services_are_ready(),
        params_result=params_result,
        rod_state_publishers=frozenset(tuple(i.endpoint_gid) for i in mon.get_publishers_info_by_topic(topics.ROD_STATE)),
        foreign=mon.foreign,
    )


def _drive(mon: Monitor, sup: Supervisor, executor: Executor, group: Any,
           on_recorder_lost: Callable[[], None] | None = None, emit: EventSink | None = None) -> str | None:
    """Run ``sup`` (:class:`~contgrasp_ros.launcher.supervision.Supervisor`, which decides) on what the
    monitor and the process group show, and perform its actions. Returns an error text or None.

    ``on_recorder_lost`` is called when the recorder died (a simulator restarted later must not
    wait for the recorder to match it); ``emit`` receives the supervisor's launcher events."""
    spin = GuardedSpin(executor, mon.drops)
    resume_fut: Any = None
    params_fut: Any = None

    def params_result() -> bool | None:
        if params_fut is None or not params_fut.done():
            return None
        return params_fut.exception() is None and all(r.successful for r in params_fut.result().results)

    while True:
        try:
            obs = _observe(mon, sup, group, resume_fut, params_result())
            for action in sup.step(obs):
                match action:
                    case Resume():
                        resume_fut = mon.pause.call_async(SetBool.Request(data=False))
                    case Restart(node=name):
                        group.restart(next(c for c in group.children if c.name == name))
                    case Unrecorded():
                        mon.recording = False
                        if on_recorder_lost is not None:
                            on_recorder_lost()
                    case SetMinSubscribers(value=value):
                        params_fut = mon.sim_params.set_parameters([Parameter("min_subscribers", value=value)])
                    case Log(level="info", text=text):
                        mon.get_logger().info(text)
                    case Log(text=text):
                        mon.get_logger().error(text)
                    case Notify(event=event, fields=fields):
                        if emit is not None:
                            emit(event, **fields)
                    case Finish():
                        pass
            if sup.done:
                return sup.error
            # every message of the period, not one (a graph query per message cost the launcher
            # more than its callbacks); a change of the simulator's state is acted on at once
            end = time.monotonic() + sup.spin_period
            mon.state_changed = False
            while not mon.state_changed and (left := end - time.monotonic()) > 0:
                spin(left)
        except (KeyboardInterrupt, ExternalShutdownException):
            raise
        except Exception as exc:  # (SIGINT shuts rclpy's context down between two calls: an interrupt)
            if mon.context.ok():
                raise
            raise ExternalShutdownException() from exc


def bag_summary(path: Path) -> dict[str, Any]:
    """What the finished recording holds: size, the clock of its log times and the time from the
    first to the last recorded message in it (``sim_time_s`` or ``wall_time_s``, the other
    ``None``), written messages per topic, the recorder's counts."""
    from contgrasp_ros.bag import BagError
    from contgrasp_ros.bag.reader import info, open_recording
    from contgrasp_ros.bag.writer import RECORDER_RECORD

    try:
        rec = open_recording(path)
        meta = info(rec)
        counts = rec.metadata_records().get(RECORDER_RECORD, {})
    except BagError as exc:
        return {"path": str(path), "error": str(exc)}
    return {
        "path": str(path),
        "size_bytes": meta["size_bytes"],
        "log_time_clock": meta["log_time_clock"],
        "sim_time_s": meta["sim_time_s"],
        "wall_time_s": meta["wall_time_s"],
        "messages": meta["message_count"],
        "received": json.loads(counts.get("received", "null")),
        "written": json.loads(counts.get("written", "null")),
        "decimated": json.loads(counts.get("decimated", "0")),
        "lost_in_transport": json.loads(counts.get("lost_in_transport", "0")),
        "topics": {t["name"]: t["count"] for t in meta["topics"]},
    }


def run_graph(
    params: dict[str, dict[str, Any]],
    *,
    in_process: bool,
    params_file: Path,
    timeout: float,
    record: dict[str, Any] | None = None,
    respawn: int = 0,
    keep_history: bool = True,
    events: EventSink | None = None,
    foxglove: int | None = None,
    allow_unrecorded: bool = False,
    compose: Sequence[tuple[str, ...]] = (),
    namespace: str = "/",
) -> tuple[dict[str, Any], int]:
    """Run the graph once (recording it when ``record`` gives an ``output``, restarting crashed
    node processes up to ``respawn`` times each); returns (summary, exit code). SIGINT/SIGTERM
    end the run early with exit code 130, everything stopped and the recording finalised.
    ``events`` receives the node processes' ``started``/``restarted``/``exited`` events and
    ``resumed`` (:mod:`contgrasp_ros.launcher.events`). ``foxglove``: serve the run live on this WebSocket
    port (:mod:`contgrasp_ros.nodes.foxglove_bridge`, in the launcher's process; 0 = any). A
    recording lost mid-run (the recorder died) fails the run (exit 1) unless ``allow_unrecorded``.
    ``compose``: groups of nodes each hosted by one process (:mod:`contgrasp_ros.nodes.container`, named
    ``a+b``), the simulator not among them; the other nodes run one per process. ``namespace``: the
    graph's, given to every node process and to this process's nodes (the monitor's, the in-process
    nodes') with the namespace's own clock (:func:`contgrasp_ros.plumbing.topics.namespace_arguments`)."""
    wall0 = time.perf_counter()
    sim_params = {**params["rod_simulator"], "start_paused": True}
    moved = topics.namespace_arguments(namespace)
    rclpy.init(args=["--ros-args", *moved] if moved else [])  # (global rules: every node of this process)
    executor = make_executor()
    nodes: list[Node] = []
    group = None
    processes: list[str] = []  # (the node processes' names, in start order: stopped in that order)
    tmp: Path | None = None
    code = 0
    mon: Monitor | None = None
    sup: Supervisor | None = None
    extra: dict[str, Any] = {}
    on_recorder_lost: Callable[[], None] | None = None
    foxglove_url = ""
    try:
        moves = sim_params.get("object_mode", "fixed") != "fixed"
        with discovery_profile_set():  # (this process's participant is created with the first node)
            mon = Monitor(history_period=0.01 if keep_history else None, recording=record is not None,
                          recorded_streams=RECORDED_STREAMS + (OBJECT_STREAMS if moves else ()),
                          own_pids=lambda: {os.getpid(), *(group.pids if group is not None else ())})
        nodes.append(mon)
        if foxglove is not None:
            from contgrasp_ros.nodes.foxglove_bridge import FoxgloveBridge

            bridge = FoxgloveBridge(parameter_overrides=_overrides({"port": foxglove, "use_sim_time": True}))
            nodes.append(bridge)
            foxglove_url = f"ws://127.0.0.1:{bridge.port}"
        if in_process:
            for name in NODES:  # (node_class imports each module now: the node processes import their own)
                values = sim_params if name == "rod_simulator" else params[name]
                try:
                    nodes.append(node_class(name)(parameter_overrides=_overrides({**values, **SUPERVISED})))
                except (rclpy.exceptions.ParameterException, ContgraspError, TypeError) as exc:
                    if isinstance(exc, RunFailure):  # as run_node exits: 1 for a failure, 2 for bad input
                        return {"error": f"{name}: {exc}", "exit_codes": {}, "pids": {}}, 1
                    return {"error": f"{name}: invalid parameter: {exc}", "exit_codes": {}, "pids": {}}, 2
            if record is not None:
                from contgrasp_ros.nodes.mcap_recorder import McapRecorder

                try:
                    nodes.append(McapRecorder(parameter_overrides=_overrides({**recorder_params(record),
                                                                                "on_finish": "supervised"})))
                except ContgraspError as exc:
                    return {"error": f"{RECORDER}: {exc}", "exit_codes": {}, "pids": {}}, exit_code(exc)
        else:
            from contgrasp_ros.launcher.processes import ProcessGroup

            env = dict(os.environ, PYTHONUNBUFFERED="1")
            use_discovery_profile(env)  # (the node processes', not this process's: contgrasp_ros.launcher.discovery)
            group = ProcessGroup(env, events=events)
            # Launcher overrides go in a second parameter file: a node's own section in the user's
            # file would beat a plain ``-p name:=value`` (rcl gives node-specific entries priority).
            # It holds each node's whole scenario too: the user's ``node:`` sections name the node
            # at the root namespace only (parameter_file keys them for the graph's namespace).
            overrides: dict[str, dict[str, Any]] = {name: {**params[name], **SUPERVISED} for name in NODES}
            # the sensor, the launcher's monitor and the recorder must hear the first state, also
            # from a restarted simulator; once the recorder has died it no longer counts
            # (``_drive`` rewrites this file before restarting the simulator)
            overrides["rod_simulator"].update(
                start_paused=True, duration=float(sim_params["duration"]),
                min_subscribers=UNRECORDED_MIN_SUBSCRIBERS + (record is not None))
            if record is not None:
                overrides[RECORDER] = {**recorder_params(record), "on_finish": "supervised"}
            tmp = Path(tempfile.mkdtemp(prefix="contgrasp_launch_"))
            override_file = parameter_file(tmp / "overrides.yaml", overrides, namespace)

            def unrecorded() -> None:  # for a restarted simulator, and the running one (_drive)
                overrides["rod_simulator"]["min_subscribers"] = UNRECORDED_MIN_SUBSCRIBERS
                parameter_file(override_file, overrides, namespace)

            on_recorder_lost = unrecorded if record is not None else None
            for proc in graph_processes(NODES, compose, record=record is not None):
                # (the recorder reads only the overrides: its own section holds all it needs)
                files = [override_file] if proc.name == RECORDER else [params_file, override_file]
                ros_args = ["--ros-args", *(a for f in files for a in ("--params-file", str(f))), *moved]
                if proc.name != RECORDER:
                    processes.append(proc.name)
                group.start(proc.name, [sys.executable, "-m", "contgrasp_ros.entry", proc.executable, *proc.arguments, *ros_args])
        for n in nodes:
            executor.add_node(n)
        sup = Supervisor(start=time.monotonic(), timeout=timeout, respawn=respawn, recording=record is not None,
                         allow_unrecorded=allow_unrecorded)
        try:
            error = _drive(mon, sup, executor, group, on_recorder_lost, events)
        except (KeyboardInterrupt, ExternalShutdownException):
            sup.interrupted()
            error, code = sup.error, 130
        extra = {"restarts": dict(sup.restarts), "faults": list(sup.faults), "launcher_errors": dict(mon.drops.counts),
                 "history": mon.history}
        if error:
            extra["error"] = error
            code = code or 1
    finally:
        summary_codes: dict[str, int] = {}
        if group is not None:
            summary_codes.update(group.stop(names=processes))  # the recorder last: it keeps what is still in flight
            summary_codes.update(group.stop())
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        join_signal_thread()  # (after the children are stopped: a SIGTERM now ends this process at once)
        executor.shutdown()
        for n in nodes:  # (in-process: the recorder was added last, so it is finalised last)
            n.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    # built from the monitor's plain values once everything is stopped (the wall time included)
    summary = {**_summary(mon, sup.loop_wall_time_s if sup else None, time.perf_counter() - wall0).to_dict(), **extra} if mon is not None else {}
    if record is not None:
        summary["bag"] = bag_summary(Path(record["output"]))
    if foxglove_url:
        summary["foxglove"] = foxglove_url
    summary["exit_codes"] = summary_codes
    summary["pids"] = {c.name: c.proc.pid for c in group.children} if group is not None else {}
    # a child's own non-zero exit code wins (negative codes are the signals we stopped it with)
    # (with allow_unrecorded a failed recorder does not fail the run)
    failing = [c for n, c in summary_codes.items() if c > 0 and not (allow_unrecorded and n == RECORDER)]
    if failing and code != 130:
        code = failing[0]
    return summary, code
