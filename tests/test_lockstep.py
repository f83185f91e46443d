"""The simulator's stepping rules without ROS (contgrasp_ros.nodes.lockstep): when step 0 goes out,
the lock-step deadline, fallback and outage counting, the re-sends until the loop closes and
the answers to a message taken again, and the free-running deadlines and wait for the couple."""

from __future__ import annotations

from contgrasp_ros.nodes.lockstep import Answered, CoupleWait, LockStep, Peers, StartGate, WallClock

LOOP = Peers(rod_state_subscribers=1, couple_publishers=1, contact_links=1)


def test_step_0_waits_for_every_peer_of_the_loop_then_a_grace_period() -> None:
    gate = StartGate(wait_for_peers=True, timeout=30.0, grace=0.5, log_period=5.0)
    go, line = gate.check(0.0, Peers(0, 0, 0), 0)
    assert not go and line is not None and "rod state subscribers 0/1" in line and "couple publishers 0/1" in line
    assert gate.check(1.0, Peers(0, 0, 0), 0) == (False, None)  # (the next line after log_period)
    go, line = gate.check(5.0, Peers(1, 0, 1), 0)
    assert not go and line is not None and "couple publishers 0/1" in line
    # a subscriber and a controller but no sensor between them: the contact topic has no link yet
    assert gate.check(6.0, Peers(1, 1, 0), 0)[0] is False
    assert gate.check(7.0, LOOP, 0)[0] is False  # matched: the grace period starts
    assert gate.check(7.4, LOOP, 0)[0] is False
    go, line = gate.check(7.5, LOOP, 0)
    assert go and line is not None and "waited 7.5 s" in line


def test_the_waiting_line_names_only_the_nodes_still_missing() -> None:
    def hint(peers: Peers) -> str:
        go, line = StartGate(wait_for_peers=True, timeout=30.0).check(0.0, peers, 0)
        assert not go and line is not None
        return line

    assert "(start boundary_sensor and grasp_controller; wait_for_peers:=false" in hint(Peers(0, 0, 0, 0))
    # the plant alone (sensor and quality node up): only the controller is missing
    line = hint(Peers(2, 0, 0, contact_publishers=1))
    assert "(start grasp_controller; " in line and "boundary_sensor" not in line
    # a controller and a recorder on the rod state, no sensor
    line = hint(Peers(1, 1, 0, contact_publishers=0))
    assert "(start boundary_sensor; " in line and "grasp_controller" not in line
    # both there, their contact endpoints not matched yet: nothing to start
    assert "(wait_for_peers:=false starts at once" in hint(Peers(1, 1, 0, contact_publishers=1))


def test_after_a_peer_joins_a_closed_loop_an_unanswered_state_goes_out_again_until_its_couple() -> None:
    rule = LockStep(resend=1.0, rejoin_resend=0.25)
    rule.published(0.0)
    rule.couple("u0", True)
    rule.published(0.0)  # state 1, unanswered: the closed loop sends nothing again by itself
    assert not rule.resend_due(5.0)
    rule.joined()  # a sensor restarted after a crash matched
    assert not rule.resend_due(0.2)  # (0.2 s after the state went out: its answer may be under way)
    assert rule.resend_due(5.0) and rule.rejoin_resent == 1
    assert not rule.resend_due(5.2) and rule.resend_due(5.25) and rule.rejoin_resent == 2
    rule.couple("u1", True)  # the loop closed again
    assert not rule.rejoined
    rule.published(6.0)
    assert not rule.resend_due(10.0) and rule.resent == 2
    # a peer that joins while the loop runs (a recorder): the answer comes first, nothing is re-sent
    rule.joined()
    rule.couple("u2", True)
    rule.published(11.0)
    assert not rule.resend_due(11.5)


def test_a_peer_that_leaves_during_the_grace_period_restarts_it() -> None:
    gate = StartGate(wait_for_peers=True, timeout=0.0, grace=0.5)
    assert not gate.check(0.0, Peers(0, 0, 0), 0)[0]
    assert not gate.check(0.1, LOOP, 0)[0]
    assert not gate.check(0.3, Peers(1, 0, 1), 0)[0]
    assert not gate.check(0.6, LOOP, 0)[0]
    assert gate.check(1.1, LOOP, 0)[0]


def test_peers_there_at_the_first_check_need_no_grace_period() -> None:
    """The launcher resumes the simulator once the graph is connected: step 0 goes out at once."""
    gate = StartGate(wait_for_peers=True, timeout=30.0, grace=0.5)
    assert gate.check(0.0, LOOP, 0)[0]


def test_min_subscribers_counts_too_and_the_timeout_starts_anyway() -> None:
    gate = StartGate(wait_for_peers=True, timeout=10.0, grace=0.0)
    assert gate.needs(3) == Peers(3, 1, 1)
    assert not gate.check(0.0, LOOP, 3)[0]
    go, line = gate.check(10.0, LOOP, 3)
    assert go and line is not None and "anyway" in line and "rod state subscribers 1/3" in line
    # timeout 0: wait for ever
    patient = StartGate(wait_for_peers=True, timeout=0.0)
    assert not patient.check(0.0, Peers(0, 0, 0), 0)[0]
    assert not patient.check(1e6, Peers(0, 0, 0), 0)[0]


def test_without_waiting_for_peers_step_0_goes_out_at_once() -> None:
    gate = StartGate(wait_for_peers=False, timeout=30.0, grace=0.5)
    assert gate.needs(0) == Peers(0, 0, 0)
    assert gate.check(0.0, Peers(0, 0, 0), 0)[0]
    # ... but min_subscribers still holds it back (a restarted simulator in the launcher)
    gate.restart()
    assert not gate.check(0.0, Peers(1, 0, 0), 2)[0]
    assert not gate.check(0.2, Peers(2, 0, 0), 2)[0]
    assert gate.check(0.75, Peers(2, 0, 0), 2)[0]


def test_lockstep_deadline_fallback_and_outage() -> None:
    rule = LockStep()
    assert not rule.started and rule.tick(100.0, 1.0) is False  # nothing published: no deadline
    rule.published(0.0)
    assert rule.started and rule.tick(1.0, 1.0) is False  # (strictly later than the timeout)
    assert rule.tick(1.01, 1.0) is True and rule.missed == 1 and rule.first_of_outage
    assert rule.tick(5.0, 1.0) is False  # the fallback was applied: no deadline until the next state
    rule.published(5.0)
    assert rule.tick(6.5, 1.0) is True and rule.missed == 2 and not rule.first_of_outage
    rule.published(6.5)
    u, ended = rule.couple("u2", can_step=True)
    assert u == "u2" and ended == 2 and rule.outage == 0
    rule.published(6.6)
    assert rule.couple("u3", can_step=True) == ("u3", 0)


def test_a_couple_that_arrives_while_paused_is_applied_on_resume() -> None:
    rule = LockStep()
    rule.published(0.0)
    assert rule.couple("u0", can_step=False) == (None, 0)
    assert rule.resume(3.0) == "u0" and rule.pending is None
    # resumed with nothing pending: the deadline counts from the resume, not from the publication
    rule.published(4.0)
    assert rule.resume(10.0) is None
    assert rule.tick(10.5, 1.0) is False and rule.tick(11.1, 1.0) is True


def test_stop_and_reset() -> None:
    rule = LockStep()
    rule.published(0.0)
    rule.stop()
    assert rule.tick(100.0, 1.0) is False
    rule.published(100.0)
    assert rule.tick(200.0, 1.0) is True and rule.missed == 1
    rule.couple("u", can_step=False)
    rule.reset()
    assert (rule.started, rule.missed, rule.outage, rule.pending, rule.waiting_since) == (False, 0, 0, None, None)


def test_an_unanswered_state_is_sent_again_until_the_loop_closes() -> None:
    """A peer whose reader matched after a state went out never gets it: until the run's first
    couple the awaited state goes out again every ``resend`` seconds (from its last sending);
    the re-sends do not move the couple's deadline; after the first couple, nothing again."""
    rule = LockStep(resend=1.0)
    assert rule.resend_due(100.0) is False  # nothing published
    rule.published(0.0)
    assert rule.resend_due(0.99) is False
    assert rule.resend_due(1.0) is True and rule.resent == 1
    assert rule.resend_due(1.5) is False  # (a period from the re-send)
    assert rule.resend_due(2.0) is True and rule.resent == 2
    assert rule.tick(10.01, 10.0) is True  # the deadline still counts from the first sending
    assert rule.resend_due(20.0) is False  # (the fallback moves on: the next state is published)
    rule.published(20.0)  # step 1 after the fallback: the loop is still open
    assert rule.resend_due(21.0) is True and rule.resent == 3
    assert rule.couple("u1", can_step=True) == ("u1", 1) and rule.closed
    rule.published(21.1)
    assert rule.resend_due(1e6) is False and rule.resent == 3  # closed: every hop has delivered
    rule.reset()  # a new run: open again
    assert not rule.closed and rule.resent == 0
    rule.published(0.0)
    assert rule.resend_due(1.0) is True


def test_a_couple_kept_while_paused_closes_the_loop_and_a_stopped_run_sends_nothing() -> None:
    rule = LockStep(resend=1.0)
    rule.published(0.0)
    rule.couple("u0", can_step=False)
    assert rule.closed and rule.resend_due(5.0) is False
    rule.reset()
    rule.published(0.0)
    rule.stop()  # (finished or failed)
    assert rule.resend_due(5.0) is False


def test_answered_recognises_the_same_message_only() -> None:
    answered = Answered()
    assert not answered.again(b"state 1") and not answered.again(None)
    answered.keep(b"state 1", b"contact 1")
    assert answered.again(bytes(b"state 1")) and answered.answer == b"contact 1"  # (equal, not the same object)
    assert not answered.again(b"state 1 of another rod")  # (same step and stamp, other content: no repeat)
    answered.keep(b"state 2", b"contact 2")
    assert not answered.again(b"state 1")  # only the newest is kept
    answered.reset()
    assert not answered.again(b"state 2") and answered.answer == b""


def test_wall_clock_counts_every_period_lost_once() -> None:
    """Free-running: jitter inside a period is on time; each whole period lost is one miss and
    the schedule moves on by it; the first step's own delay does not hide a later lost tick; a
    pause is not lost time; reset clears the count."""
    w = WallClock(0.002)
    assert [w.step(t) for t in (10.0, 10.0021, 10.0049, 10.0061)] == [0, 0, 0, 0]  # due 10, .002, .004, .006
    assert w.step(10.0111) == 1 and w.missed == 1  # due 10.008: one period and 1.1 ms behind
    assert [w.step(t) for t in (10.0121, 10.0141)] == [0, 0]  # the schedule moved on by one period
    assert w.step(10.0221) == 3 and w.missed == 4  # due 10.0141 + 2 ms: three more periods lost
    w.restart()  # paused for a second
    assert [w.step(t) for t in (11.5, 11.502)] == [0, 0] and w.missed == 4
    w.reset()
    # the first step began 0.5 ms late, the next on its tick, then one tick was skipped
    assert [w.step(t) for t in (20.0005, 20.002, 20.006)] == [0, 0, 1] and w.missed == 1


def test_a_free_running_step_waits_for_its_own_answer_and_counts_the_steps_that_go_without() -> None:
    """CoupleWait: a tick whose answer is in steps at once; one without waits; an answer to an
    older state does not end the wait, the awaited one does; a wait that runs out steps with the
    newest couple and is counted late, once; a pause cancels the wait uncounted; reset clears."""
    w = CoupleWait(wait=True)
    assert w.tick(0) is False  # (no answer yet)
    assert w.couple(0) is True and w.late == 0  # the awaited answer: step now
    assert w.tick(1) is False
    assert w.couple(0) is False  # (a stale answer: still waiting)
    assert w.couple(1) is True
    w.couple(2)  # (an answer before its tick)
    assert w.tick(2) is True and w.expired() is False and w.late == 0
    assert w.tick(3) is False and w.expired() is True and w.late == 1
    assert w.expired() is False and w.late == 1  # (nothing waits any more)
    assert w.couple(3) is False  # (its step went on without it)
    assert w.tick(4) is False
    w.cancel()  # paused while waiting
    assert w.expired() is False and w.couple(4) is False and w.late == 1
    w.reset()
    assert (w.answered, w.awaited, w.late) == (-1, None, 0)


def test_without_a_wait_every_tick_steps_at_once_and_counts_the_missing_answers() -> None:
    w = CoupleWait(wait=False)
    w.couple(0)
    assert [w.tick(0), w.tick(1), w.tick(2)] == [True, True, True]
    assert w.late == 2 and w.expired() is False
