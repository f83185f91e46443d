"""The rod simulator's stepping rules as plain logic (no rclpy), so they are unit-tested alone.

:class:`StartGate`: when step 0 may go out (the loop's peers matched, so a graph started by hand
runs like the launcher's). :class:`LockStep`: state k out, wait for the couple answering it,
resend while unanswered, fall back after the couple timeout. :class:`Answered`: a state sent twice
gets the same answer. :class:`WallClock` and :class:`CoupleWait`: the free-running rule
(``lockstep: false``). The node (:mod:`contgrasp_ros.nodes.rod_simulator`) feeds them monotonic
wall-clock times and what it sees of the graph. docs/ros.md ("Lock-step", "Step 0 waits for the loop").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Peers", "StartGate", "LockStep", "Answered", "WallClock", "CoupleWait"]

# Wall seconds between two sendings of a state that waits for its couple before the loop has
# closed (LockStep): far above the loop's first round trip (milliseconds; a re-send whose
# original was only slow is a duplicate, harmless but recorded), far below the couple timeout.
RESEND_S = 1.0
# Wall seconds a state may stay unanswered after a peer of the loop (re)joined mid-run before it
# goes out again (LockStep.joined; and again as often while unanswered): far above a step's round
# trip (~2 ms), so a joining recorder or monitor costs no duplicate, and short against the stall.
REJOIN_RESEND_S = 0.25


@dataclass(frozen=True)
class Peers:
    """What the simulator sees of the closed loop: subscribers of its rod state (the sensor, a
    recorder, a monitor), the contact topic's links (the fewer of its publishers and subscribers
    in the graph: the sensor and the controller), publishers of couples (the controller) and of
    contact states (the sensor)."""

    rod_state_subscribers: int
    couple_publishers: int
    contact_links: int = 0
    contact_publishers: int = 0


class StartGate:
    """When step 0 may be published.

    With ``wait_for_peers`` the loop's peers must be there: at least ``max(1, min_subscribers)``
    subscribers of the rod state, a contact publisher and subscriber, and a couple publisher;
    without it only ``min_subscribers`` subscribers. Once they are there, ``grace`` more seconds pass (discovery runs ahead of the
    endpoints' matching, and a state published before a reader matched is not delivered to it).
    After ``timeout`` seconds of waiting (0 = never) step 0 goes out anyway. While waiting a log
    line every ``log_period`` seconds says what is missing.
    """

    def __init__(self, *, wait_for_peers: bool, timeout: float, grace: float = 0.5, log_period: float = 5.0) -> None:
        self.wait_for_peers = wait_for_peers
        self.timeout = timeout
        self.grace = grace
        self.log_period = log_period
        self.restart()

    def restart(self) -> None:
        """Wait again (a reset run's first state)."""
        self._since: float | None = None  # first check
        self._matched_since: float | None = None
        self._next_log = 0.0

    def needs(self, min_subscribers: int) -> Peers:
        """The peers step 0 waits for."""
        if self.wait_for_peers:
            return Peers(max(1, min_subscribers), 1, 1)
        return Peers(min_subscribers, 0, 0)

    def check(self, now: float, peers: Peers, min_subscribers: int) -> tuple[bool, str | None]:
        """(step 0 may go out now, a line to log or None)."""
        need = self.needs(min_subscribers)
        first = self._since is None
        if self._since is None:
            self._since = now
        if (peers.rod_state_subscribers >= need.rod_state_subscribers and peers.couple_publishers >= need.couple_publishers
                and peers.contact_links >= need.contact_links):
            if self._matched_since is None:
                # peers that were there before the first check (a launcher resuming the
                # simulator, a reset) have matched long since: no grace period for them
                self._matched_since = now - (self.grace if first else 0.0)
            if now - self._matched_since >= self.grace or need == Peers(0, 0, 0):
                return True, f"publishing step 0 ({_have(peers, need)}; waited {now - self._since:.1f} s)"
            return False, None
        self._matched_since = None
        waited = now - self._since
        if self.timeout > 0 and waited >= self.timeout:
            return True, (f"no peers after {waited:.1f} s ({_have(peers, need)}): publishing step 0 anyway "
                          "(peer_timeout); without a controller the lock-step loop applies its timeout fallback")
        if now >= self._next_log:
            self._next_log = now + self.log_period
            limit = f"; publishing anyway after peer_timeout = {self.timeout:g} s" if self.timeout > 0 else ""
            return False, (f"waiting for the closed loop's peers before publishing step 0: {_have(peers, need)} "
                           f"({_absent(peers, need)}wait_for_peers:=false starts at once{limit})")
        return False, None


def _absent(peers: Peers, need: Peers) -> str:
    """The hint naming the loop's nodes not seen yet ('' when each is there, still matching): the
    sensor is the one contact publisher, the controller the one couple publisher."""
    missing = [name for name, absent in (("boundary_sensor", need.contact_links > peers.contact_publishers),
                                         ("grasp_controller", need.couple_publishers > peers.couple_publishers)) if absent]
    return f"start {' and '.join(missing)}; " if missing else ""


def _have(peers: Peers, need: Peers) -> str:
    return (f"rod state subscribers {peers.rod_state_subscribers}/{need.rod_state_subscribers}, "
            f"contact links {peers.contact_links}/{need.contact_links}, "
            f"couple publishers {peers.couple_publishers}/{need.couple_publishers}")


class LockStep:
    """The lock-step rule between the state published for step k and the couple answering it.

    ``published(now)`` after each state; ``couple(u, can_step)`` for a couple that passed
    validation (its step is the current one) returns the couple to apply now, or None (kept
    until ``resume``); ``tick(now, timeout)`` returns True when the deadline passed, the miss
    counted (apply the fallback); ``stop()`` when the run finished or failed.

    ``resend_due(now)`` returns True when the awaited state is to be published again: the loop
    has not closed yet (no couple in this run) and ``resend`` seconds passed since the state
    last went out. A state goes out on a volatile topic once the simulator's writer matched the
    sensor's reader, but the sensor's reader may match the writer later, and a sample sent
    before that is lost to it (the same for the sensor's contact state on its way to the
    controller, and for the couple on its way back). The run's first couple proves every hop
    matched both ways; from then on a state is re-sent only after ``joined()``: a peer of the
    loop (re)joined mid-run (a sensor or controller restarted after a crash), which missed the
    awaited state; it goes out again once it has been unanswered ``rejoin_resend`` seconds, and
    as often until a couple answers. ``resent`` counts the re-sends of the run.
    """

    def __init__(self, resend: float = RESEND_S, rejoin_resend: float = REJOIN_RESEND_S) -> None:
        self.resend = resend
        self.rejoin_resend = rejoin_resend
        self.missed = 0  # deadlines missed in this run
        self.outage = 0  # consecutive missed deadlines (the current outage)
        self.reset()

    def reset(self) -> None:
        """A new run: nothing published, nothing pending, the loop open (the miss counts start
        over too)."""
        self.started = False
        self.closed = False  # a couple answered a state of this run
        self.rejoined = False  # a peer joined since the last couple
        self.rejoin_resent = 0  # re-sends since then
        self.waiting_since: float | None = None
        self.sent_at: float | None = None  # when the awaited state last went out
        self.pending: Any = None
        self.missed = 0
        self.outage = 0
        self.resent = 0

    def published(self, now: float) -> None:
        """A state went out: its couple is due within the timeout from now."""
        self.started = True
        self.waiting_since = self.sent_at = now

    def joined(self) -> None:
        """A peer of the loop matched (a rod-state subscriber, a couple publisher): the awaited
        state is re-sent when unanswered, until the next couple."""
        if not self.rejoined:
            self.rejoined, self.rejoin_resent = True, 0

    def resend_due(self, now: float) -> bool:
        """True when the awaited state goes out again (counted in ``resent``)."""
        period = self.rejoin_resend if self.closed else self.resend
        if ((self.closed and not self.rejoined) or self.waiting_since is None or self.sent_at is None
                or now - self.sent_at < period):
            return False
        self.sent_at = now
        self.resent += 1
        if self.closed:
            self.rejoin_resent += 1
        return True

    def stop(self) -> None:
        """The run is over: no deadline any more."""
        self.waiting_since = None

    def couple(self, u: Any, can_step: bool) -> tuple[Any, int]:
        """A valid couple for the current step: (apply it now or None = kept, length of the outage
        it ends, 0 if none)."""
        self.closed = True
        self.rejoined = False
        ended, self.outage = self.outage, 0
        if can_step:
            return u, ended
        self.pending = u
        return None, ended

    def resume(self, now: float) -> Any:
        """Unpaused: the couple kept while paused, to apply now; else the deadline restarts."""
        u, self.pending = self.pending, None
        if u is None and self.started:
            self.waiting_since = now
        return u

    def tick(self, now: float, timeout: float) -> bool:
        """True when the couple is overdue: the miss is counted, apply the fallback (and
        ``first_of_outage`` tells whether to log it)."""
        if self.waiting_since is None or now - self.waiting_since <= timeout:
            return False
        self.missed += 1
        self.outage += 1
        self.waiting_since = None
        return True

    @property
    def first_of_outage(self) -> bool:
        """The last miss began an outage (log it once; its length is logged when couples return)."""
        return self.outage == 1


class Answered:
    """The loop message a node took last, as it came (serialized, or a typed message), and what
    the node published in answer (serialized), so the same message taken again - equal, byte
    for byte: a state :class:`LockStep` re-sent, or an answer to it, which carries its step and
    stamp - is recognised: the sensor and the controller publish their answer again (a hop
    after theirs may be the one that lost it) without computing it twice; the simulator ignores
    a second couple equal to the one it took. A different message with the same step and stamp
    (another controller's couple, a restarted simulator's other rod) is no repeat."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Nothing taken yet."""
        self.message: Any = None
        self.answer = b""

    def again(self, message: Any) -> bool:
        """Whether ``message`` is the one taken last."""
        return self.message is not None and message == self.message

    def keep(self, message: Any, answer: bytes = b"") -> None:
        """``message`` was taken (and answered with ``answer``)."""
        self.message, self.answer = message, answer


class WallClock:
    """The free-running rule: step k of a schedule is due ``k`` control periods of wall time
    after the schedule's origin. ``step(now)`` when a step begins returns how many whole periods
    the simulation has fallen behind that schedule (0: on time) and counts them as missed
    deadlines; the schedule then moves on by as much, so each lost period counts once. Timer
    ticks are late, never early: a step that begins earlier against the schedule than any
    before moves its origin back (the first step's own delay must not hide a later lost tick).
    ``restart()`` after a pause (the pause is not lost time); ``reset()`` for a new run."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.reset()

    def reset(self) -> None:
        """A new run: no schedule, no misses."""
        self.missed = 0
        self.restart()

    def restart(self) -> None:
        """The next step starts a new schedule."""
        self.origin: float | None = None
        self.k = 0

    def step(self, now: float) -> int:
        """A step begins at ``now`` (wall seconds, monotonic): the periods lost before it."""
        if self.origin is None:
            self.origin, self.k = now, 0
        self.origin = min(self.origin, now - self.k * self.period)
        behind = max(int((now - self.origin - self.k * self.period) // self.period), 0)  # (>= 0 but for rounding)
        if behind > 0:
            self.missed += behind
            self.origin += behind * self.period
        self.k += 1
        return behind


class CoupleWait:
    """Free-running mode's wait for the couple answering the current state (step k's couple,
    computed from state k).

    The sensor and the controller answer a state about a millisecond after it goes out. A step
    whose tick comes before that answer and goes on at once with the older couple (the law
    linearised about state k - 1) is harder for the rod engine: at the start of the grasp two
    to four times the Newton iterations. It then runs past the next tick, whose step again
    starts before its answer, and the simulation falls ever further behind the wall clock
    (docs/ros.md). So a step waits for its answer, up to the node's ``couple_wait`` (a part
    of the control period) from its tick, then goes on with the newest couple it has: a late
    couple, counted in ``late``.

    The node calls ``tick(k)`` at step k's tick (True: step now), ``couple(step)`` for every
    valid couple (True: the awaited answer, step now), ``expired()`` when the wait has
    passed since a tick that returned False (True: step now with the newest couple),
    ``cancel()`` when the run pauses, ``reset()`` for a new run. With ``wait`` False
    (``couple_wait`` 0) every tick steps at once (without its answer: late, counted).
    """

    def __init__(self, wait: bool) -> None:
        self.wait = wait
        self.reset()

    def reset(self) -> None:
        """A new run: no answer yet, nothing awaited, no late couples."""
        self.answered = -1  # the newest step a couple answered
        self.awaited: int | None = None  # the step whose answer a tick is waiting for
        self.late = 0  # steps that went on with an older couple

    def tick(self, k: int) -> bool:
        """Step k's tick: True when it may step now (its answer is in; or no waiting: a late
        couple, counted)."""
        self.awaited = None
        if self.answered >= k:
            return True
        if not self.wait:
            self.late += 1
            return True
        self.awaited = k
        return False

    def couple(self, step: int) -> bool:
        """A valid couple answering ``step``: True when it is the awaited one (step now)."""
        self.answered = max(self.answered, step)
        if self.awaited is not None and step >= self.awaited:
            self.awaited = None
            return True
        return False

    def expired(self) -> bool:
        """The wait is over without the answer: True when a step was waiting (step now with the
        newest couple, counted late)."""
        if self.awaited is None:
            return False
        self.awaited = None
        self.late += 1
        return True

    def cancel(self) -> None:
        """No step waits any more (paused)."""
        self.awaited = None
