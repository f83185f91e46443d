"""The launcher's supervision of one graph run as a plain state machine (no rclpy).

:class:`Supervisor` decides, ``graph_run._drive`` observes and acts: each tick it hands
:meth:`Supervisor.step` an :class:`Observation` (time, exited processes, graph connected, the
simulator's status, service answers, rod-state publishers) and performs the returned actions
(:class:`Resume`, :class:`Restart`, :class:`Unrecorded`, :class:`SetMinSubscribers`,
:class:`Log`, :class:`Notify`, :class:`Finish`). The run goes through the phases (:class:`Phase`)
``CONNECTING``, ``RESUMING``, ``RUNNING``, ``SETTLING`` and ``DONE``; the rules for restarts, a
lost recorder and timeouts are in docs/design.md ("One run summary") and docs/ros.md ("Running").
"""

from __future__ import annotations

import enum
from collections.abc import Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "RECORDER",
    "SIMULATOR",
    "Phase",
    "Exit",
    "Observation",
    "Resume",
    "Restart",
    "Unrecorded",
    "SetMinSubscribers",
    "Log",
    "Notify",
    "Finish",
    "Action",
    "Supervisor",
]

SIMULATOR = "rod_simulator"
RECORDER = "mcap_recorder"
RESUME_GRACE_S = 1.0  # after a restarted simulator's publisher is discovered, before resuming it
RESUME_RETRY_S = 2.0  # resend the resume call when no answer came within this time
SETTLE_S = 1.0  # after the end, for the last contact and quality to arrive
UNRECORDED_MIN_SUBSCRIBERS = 3  # rod-state subscribers: the sensor (per step and sampled), the launcher's monitor (sampled)


class Phase(enum.Enum):
    CONNECTING = "connecting"
    RESUMING = "resuming"
    RUNNING = "running"
    SETTLING = "settling"
    DONE = "done"


@dataclass(frozen=True)
class Exit:
    """A node process that has exited: its name, pid and exit code (negative: the signal)."""

    node: str
    pid: int
    code: int


@dataclass(frozen=True)
class Observation:
    """What the driver saw after spinning once.

    ``exited`` may list the same process again on later ticks (each pid is handled once);
    ``connected`` is only read while connecting; ``resume_answered`` says whether the latest
    :class:`Resume` call has been answered, ``params_result`` the outcome of the latest
    :class:`SetMinSubscribers` call (``None`` while it is pending); ``rod_state_publishers``
    identifies the publishers of the rod state (e.g. their endpoint gids); ``foreign`` names a
    node of the graph whose status came from a process the launcher did not start, and that
    process's pid (another graph in the same domain and namespace), or is None."""

    now: float
    exited: tuple[Exit, ...] = ()
    connected: bool = False
    simulator_state: str | None = None
    simulator_message: str = ""
    pause_ready: bool = False
    resume_answered: bool = False
    params_ready: bool = False
    params_result: bool | None = None
    rod_state_publishers: frozenset[Hashable] = frozenset()
    foreign: tuple[str, int] | None = None


@dataclass(frozen=True)
class Resume:
    """Call the simulator's ``~/pause`` service with ``false`` (it replaces the previous call)."""


@dataclass(frozen=True)
class Restart:
    """Start the exited node process ``node`` again with the same command."""

    node: str


@dataclass(frozen=True)
class Unrecorded:
    """The recorder is gone: stop requiring it (graph connection, a restarted simulator's
    parameters)."""


@dataclass(frozen=True)
class SetMinSubscribers:
    """Set the running simulator's ``min_subscribers`` parameter (it replaces the previous call)."""

    value: int


@dataclass(frozen=True)
class Log:
    """A line for the launcher's log (``level``: ``info`` or ``error``)."""

    level: str
    text: str


@dataclass(frozen=True)
class Notify:
    """A machine-readable launcher event (``event`` and its fields)."""

    event: str
    fields: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Finish:
    """The run is over: ``error`` is None on success, else what ended it."""

    error: str | None


Action = Resume | Restart | Unrecorded | SetMinSubscribers | Log | Notify | Finish


class Supervisor:
    """Decides what the launcher does during one run (see the module docstring).

    ``start`` is the time of the first observation's clock at which the run began; the run
    times out at ``start + timeout``. ``restarts`` (per node), ``faults`` (one entry per exit:
    node, exit code, action taken), ``lost`` (nodes the run goes on without), ``recording``,
    ``started`` (the simulator was first resumed), ``error`` and ``loop_wall_time_s`` (from the
    first resume call to the end, in the observations' clock) are readable throughout.
    ``recording_lost`` names a recorder that died; unless ``allow_unrecorded`` the run's
    ``error`` is that, when nothing else went wrong."""

    def __init__(self, *, start: float, timeout: float, respawn: int = 0, recording: bool = False,
                 allow_unrecorded: bool = False) -> None:
        self.deadline = start + timeout
        self.respawn = respawn
        self.recording = recording
        self.allow_unrecorded = allow_unrecorded
        self.recording_lost: str | None = None
        self.phase = Phase.CONNECTING
        self.started = False
        self.restarts: dict[str, int] = {}
        self.faults: list[dict[str, Any]] = []
        self.lost: set[str] = set()
        self.error: str | None = None
        self.loop_wall_time_s: float | None = None
        self._handled: set[int] = set()
        self._loop_start = 0.0
        self._settle_end = 0.0
        # a restarted simulator waiting to be resumed
        self._resume_pending = False
        self._old_publishers: frozenset[Hashable] = frozenset()
        self._seen: float | None = None
        self._resume_sent: float | None = None
        # lowering the simulator's min_subscribers after the recorder died
        self._lower_pending = False
        self._lower_sent = False

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    @property
    def spin_period(self) -> float:
        """How long the driver spins between observations: 10 ms while connecting and resuming
        (nothing else wakes it then, and each poll's delay adds to the start-up), 20 ms while
        settling, else 50 ms."""
        if self.phase in (Phase.CONNECTING, Phase.RESUMING):
            return 0.01
        return 0.02 if self.phase is Phase.SETTLING else 0.05

    @property
    def resume_pending(self) -> bool:
        """A restarted simulator has not been resumed yet."""
        return self._resume_pending

    def step(self, obs: Observation) -> list[Action]:
        """Decide on one observation; the actions in the order to perform them."""
        out: list[Action] = []
        if obs.foreign is not None and not self.done:
            # (e.g. two controllers answering each state, one simulator's couples reaching the
            # other's: neither run is what it claims to be)
            node, pid = obs.foreign
            self._finish(f"another graph's {node} (pid {pid}) runs in this domain and namespace, so the two "
                         "runs' messages mix: give each graph its own --namespace or --domain-id", out)
            return out
        if self.phase is Phase.CONNECTING:
            if self._lower_pending:
                self._lower(obs, out)
            if not self._exits(obs, out) and not self._timed_out(obs, out, "timed out waiting for the graph to connect"):
                if obs.connected:
                    self.phase, self._loop_start = Phase.RESUMING, obs.now
                    out.append(Resume())
        elif self.phase is Phase.RESUMING:
            if not self._exits(obs, out) and not self._timed_out(obs, out, "timed out resuming the simulator"):
                if obs.resume_answered:
                    self.phase, self.started = Phase.RUNNING, True
                    out += [Log("info", "graph connected; the simulator is running"), Notify("resumed", {"restart": False})]
        elif self.phase is Phase.RUNNING:
            if self._exits(obs, out):
                return out
            if self._resume_pending:
                self._resume_restarted(obs, out)
            if self._lower_pending:
                self._lower(obs, out)
            if self._timed_out(obs, out, "wall-clock timeout"):
                return out
            if obs.simulator_state in ("finished", "failed") and not self._resume_pending:
                self.loop_wall_time_s = obs.now - self._loop_start
                self.phase, self._settle_end = Phase.SETTLING, obs.now + SETTLE_S
        elif self.phase is Phase.SETTLING:
            if obs.now >= self._settle_end:
                failed = obs.simulator_state == "failed"
                self._finish(f"simulator failed: {obs.simulator_message}" if failed else None, out)
        return out

    def interrupted(self) -> None:
        """The launcher was interrupted (SIGINT/SIGTERM): the run ends with that error."""
        if not self.done:
            self.phase, self.error = Phase.DONE, "interrupted"

    # -- the rules

    def _finish(self, error: str | None, out: list[Action]) -> None:
        if error is None and self.recording_lost is not None and not self.allow_unrecorded:
            error = f"{self.recording_lost}: the run is not recorded (--allow-unrecorded accepts that)"
        self.phase, self.error = Phase.DONE, error
        out.append(Finish(error))

    def _timed_out(self, obs: Observation, out: list[Action], text: str) -> bool:
        if obs.now > self.deadline:
            self._finish(text, out)
            return True
        return False

    def _exits(self, obs: Observation, out: list[Action]) -> bool:
        """Handle newly exited processes; True when that ended the run."""
        for e in _new(obs.exited, self._handled):
            self._handled.add(e.pid)
            if e.node == RECORDER:
                if self.recording:  # a failed recorder is reported, but the run goes on without it
                    self.recording = False
                    self.recording_lost = f"the recorder exited with code {e.code}"
                    self._fault(e, "continued unrecorded", out)
                    out += [Log("error", f"the recorder exited with code {e.code}; the run continues unrecorded"),
                            Unrecorded()]
                    self._lower_pending, self._lower_sent = True, False
                continue
            n = self.restarts.get(e.node, 0)
            if n >= self.respawn:
                if e.node == SIMULATOR or not self.started:  # (before the start the graph cannot connect)
                    self._fault(e, "run ended", out)
                    self._finish(f"node '{e.node}' exited with code {e.code}", out)
                    return True
                # the simulator's lock-step timeout applies its fallback couple from now on
                self.lost.add(e.node)
                self._fault(e, "continued without it", out)
                out.append(Log("error", f"node '{e.node}' exited with code {e.code}; the run continues without it "
                                        "(the simulator applies its timeout fallback)"))
                continue
            self.restarts[e.node] = n + 1
            self._fault(e, "restarted", out)
            out += [Log("error", f"node '{e.node}' exited with code {e.code}; restarting it ({n + 1}/{self.respawn})"),
                    Restart(e.node)]
            if e.node == SIMULATOR:
                self._resume_pending, self._seen, self._resume_sent = True, None, None
                self._old_publishers = obs.rod_state_publishers
        return False

    def _fault(self, e: Exit, action: str, out: list[Action]) -> None:
        """Record an exit (the run-ending one only as an event: the summary's error names it)."""
        if action != "run ended":
            self.faults.append({"node": e.node, "exit_code": e.code, "action": action})
        out.append(Notify("exited", {"node": e.node, "pid": e.pid, "exit_code": e.code, "action": action}))

    def _resume_restarted(self, obs: Observation, out: list[Action]) -> None:
        # Wait until the new simulator's state publisher is discovered, and a grace period for
        # the subscribers (sensor, recorder) to match it, so its first state is not lost; the
        # dead simulator's service may still be listed: resend until the new one answers.
        if self._seen is None:
            if obs.rod_state_publishers - self._old_publishers:
                self._seen = obs.now
            return
        if obs.now - self._seen < RESUME_GRACE_S:
            return
        if self._resume_sent is not None and obs.resume_answered:
            self._resume_pending, self._resume_sent = False, None
            out.append(Notify("resumed", {"restart": True}))
            return
        if obs.pause_ready and (self._resume_sent is None or obs.now - self._resume_sent > RESUME_RETRY_S):
            self._resume_sent = obs.now
            out.append(Resume())

    def _lower(self, obs: Observation, out: list[Action]) -> None:
        # the running simulator must not wait for a dead recorder to match its first state
        if self._lower_sent:
            if obs.params_result is not None:
                self._lower_pending, self._lower_sent = not obs.params_result, False
        elif obs.params_ready:
            self._lower_sent = True
            out.append(SetMinSubscribers(UNRECORDED_MIN_SUBSCRIBERS))


def _new(exited: Iterable[Exit], handled: set[int]) -> list[Exit]:
    return [e for e in exited if e.pid not in handled]
