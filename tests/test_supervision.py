"""The launcher's supervision state machine (contgrasp_ros.launcher.supervision), without ROS: every
decision of a run from fed observations. tests/test_faults.py runs the same rules with real
processes."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from contgrasp_ros.launcher.supervision import (
    Action,
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

SIM, SENSOR, CTRL, REC = "rod_simulator", "boundary_sensor", "grasp_controller", "mcap_recorder"


class Run:
    """A supervisor and the observation the next tick feeds it (fields kept between ticks)."""

    def __init__(self, timeout: float = 100.0, respawn: int = 0, recording: bool = False, allow_unrecorded: bool = False) -> None:
        self.sup = Supervisor(start=0.0, timeout=timeout, respawn=respawn, recording=recording, allow_unrecorded=allow_unrecorded)
        self.obs = Observation(now=0.0, pause_ready=True, params_ready=True, rod_state_publishers=frozenset({"sim0"}))
        self.actions: list[Action] = []

    def tick(self, dt: float = 0.05, **changes: Any) -> list[Action]:
        self.obs = replace(self.obs, now=self.obs.now + dt, **changes)
        out = self.sup.step(self.obs)
        self.actions += out
        for a in out:  # as the driver does: a new call replaces the previous one, not answered yet
            if isinstance(a, Resume):
                self.obs = replace(self.obs, resume_answered=False)
            elif isinstance(a, SetMinSubscribers):
                self.obs = replace(self.obs, params_result=None)
        return out

    def start(self) -> None:
        """Connect and resume: the run is RUNNING."""
        assert self.tick() == [] and self.sup.spin_period == 0.01  # (start-up: poll often)
        assert self.tick(connected=True) == [Resume()]
        assert self.sup.phase is Phase.RESUMING and self.sup.spin_period == 0.01
        out = self.tick(resume_answered=True)
        assert out == [Log("info", "graph connected; the simulator is running"), Notify("resumed", {"restart": False})]
        assert self.sup.phase is Phase.RUNNING and self.sup.started and self.sup.spin_period == 0.05

    def kill(self, node: str, pid: int, code: int = -9) -> list[Action]:
        return self.tick(exited=(*self.obs.exited, Exit(node, pid, code)))

    def finish(self, state: str = "finished", message: str = "") -> list[Action]:
        """The simulator reports its end: settle for a second, then the final action."""
        assert self.tick(simulator_state=state, simulator_message=message) == []
        assert self.sup.phase is Phase.SETTLING and self.sup.spin_period == 0.02
        assert self.tick(0.5) == []
        return self.tick(0.6)


def events(actions: list[Action]) -> list[tuple[str, dict[str, Any]]]:
    return [(a.event, a.fields) for a in actions if isinstance(a, Notify)]


def test_a_clean_run_connects_resumes_runs_settles_and_finishes() -> None:
    run = Run()
    run.start()
    assert run.tick(simulator_state="running") == [] and run.sup.phase is Phase.RUNNING
    assert run.finish() == [Finish(None)]
    assert run.sup.done and run.sup.error is None
    assert run.sup.loop_wall_time_s == pytest.approx(0.15)  # from the resume call (t = 0.1) to the end
    assert run.sup.restarts == {} and run.sup.faults == []


def test_a_failed_simulator_fails_the_run_with_its_message() -> None:
    run = Run()
    run.start()
    assert run.finish("failed", "Newton did not converge") == [Finish("simulator failed: Newton did not converge")]
    assert run.sup.error == "simulator failed: Newton did not converge"


@pytest.mark.parametrize(("before", "text"), [(0, "timed out waiting for the graph to connect"),
                                              (1, "timed out resuming the simulator"),
                                              (2, "wall-clock timeout")])
def test_timeouts_name_the_phase(before: int, text: str) -> None:
    run = Run(timeout=10.0)
    if before >= 1:
        assert run.tick(connected=True) == [Resume()]
    if before >= 2:
        run.tick(resume_answered=True)
    assert run.tick(9.0) == []
    assert run.tick(1.1) == [Finish(text)]
    assert run.sup.done and run.sup.error == text


def test_a_node_dying_before_the_start_ends_the_run() -> None:
    """Without respawn the graph cannot connect without the node: no 'continued without it'."""
    run = Run()
    out = run.kill(SENSOR, 11, 2)
    assert out[-1] == Finish("node 'boundary_sensor' exited with code 2")
    assert events(out) == [("exited", {"node": SENSOR, "pid": 11, "exit_code": 2, "action": "run ended"})]
    assert run.sup.faults == []  # (the error names it)


def test_a_node_dying_while_resuming_ends_the_run() -> None:
    run = Run()
    run.tick(connected=True)
    assert run.kill(CTRL, 12)[-1] == Finish("node 'grasp_controller' exited with code -9")


def test_simulator_death_without_respawn_ends_the_run() -> None:
    run = Run()
    run.start()
    assert run.kill(SIM, 10) == [Notify("exited", {"node": SIM, "pid": 10, "exit_code": -9, "action": "run ended"}),
                                 Finish("node 'rod_simulator' exited with code -9")]
    assert run.sup.done


def test_sensor_death_beyond_respawn_continues_without_it() -> None:
    run = Run()
    run.start()
    out = run.kill(SENSOR, 11)
    assert out == [Notify("exited", {"node": SENSOR, "pid": 11, "exit_code": -9, "action": "continued without it"}),
                   Log("error", "node 'boundary_sensor' exited with code -9; the run continues without it "
                                "(the simulator applies its timeout fallback)")]
    assert run.sup.lost == {SENSOR} and run.sup.phase is Phase.RUNNING
    assert run.sup.faults == [{"node": SENSOR, "exit_code": -9, "action": "continued without it"}]
    assert run.tick() == []  # the same exit, seen again, is handled once
    assert run.finish() == [Finish(None)]


def test_dead_nodes_are_restarted_up_to_respawn_times_then_the_run_goes_on_without_them() -> None:
    run = Run(respawn=2)
    run.start()
    out = run.kill(CTRL, 12)
    assert out[1:] == [Log("error", "node 'grasp_controller' exited with code -9; restarting it (1/2)"), Restart(CTRL)]
    assert run.kill(CTRL, 13)[-1] == Restart(CTRL)  # the restarted process (new pid) dies too
    out = run.kill(CTRL, 14)
    assert Restart(CTRL) not in out and run.sup.lost == {CTRL}
    assert run.sup.restarts == {CTRL: 2}
    assert [f["action"] for f in run.sup.faults] == ["restarted", "restarted", "continued without it"]
    assert not run.sup.resume_pending  # a controller restart needs no resume
    assert run.finish() == [Finish(None)]


def test_recorder_death_continues_unrecorded_and_lowers_min_subscribers() -> None:
    run = Run(respawn=3, recording=True, allow_unrecorded=True)
    run.start()
    out = run.kill(REC, 20, 1)
    assert out == [Notify("exited", {"node": REC, "pid": 20, "exit_code": 1, "action": "continued unrecorded"}),
                   Log("error", "the recorder exited with code 1; the run continues unrecorded"),
                   Unrecorded(), SetMinSubscribers(UNRECORDED_MIN_SUBSCRIBERS)]
    assert not run.sup.recording and REC not in run.sup.restarts  # never restarted
    assert run.tick() == []  # waiting for the parameter service's answer
    assert run.tick(params_result=False) == []  # refused: try again
    assert run.tick() == [SetMinSubscribers(UNRECORDED_MIN_SUBSCRIBERS)]
    assert run.tick(params_result=True) == []
    assert run.tick() == [] and run.finish() == [Finish(None)]
    assert run.sup.faults == [{"node": REC, "exit_code": 1, "action": "continued unrecorded"}]


def test_a_lost_recording_fails_the_run_unless_allowed() -> None:
    """The run goes on without the recorder, but ends with an error (exit 1) that names it;
    ``allow_unrecorded`` (--allow-unrecorded) accepts an unrecorded run."""
    run = Run(recording=True)
    run.start()
    run.kill(REC, 20, -9)
    run.tick(params_result=True)
    assert not run.sup.done and run.sup.recording_lost == "the recorder exited with code -9"
    error = "the recorder exited with code -9: the run is not recorded (--allow-unrecorded accepts that)"
    assert run.finish() == [Finish(error)] and run.sup.error == error
    # a run that failed anyway keeps its own error
    run = Run(recording=True)
    run.start()
    run.kill(REC, 20, -9)
    assert run.kill(SIM, 10)[-1] == Finish("node 'rod_simulator' exited with code -9")
    # allowed: a clean finish
    run = Run(recording=True, allow_unrecorded=True)
    run.start()
    run.kill(REC, 20, -9)
    assert run.finish() == [Finish(None)] and run.sup.error is None


def test_recorder_death_while_connecting_lowers_once_the_parameter_service_is_ready() -> None:
    run = Run(recording=True)
    run.obs = replace(run.obs, params_ready=False)
    out = run.kill(REC, 20, 1)
    assert Unrecorded() in out and SetMinSubscribers(UNRECORDED_MIN_SUBSCRIBERS) not in out and not run.sup.done
    assert run.tick() == []
    assert run.tick(params_ready=True) == [SetMinSubscribers(UNRECORDED_MIN_SUBSCRIBERS)]
    assert run.tick(params_result=True) == []
    assert run.tick(connected=True) == [Resume()]  # the graph connects without the recorder


def test_a_recorder_exit_of_an_unrecorded_run_is_ignored() -> None:
    run = Run(recording=False)
    run.start()
    assert run.kill(REC, 20, 0) == [] and run.sup.faults == []


def test_restarted_simulator_is_resumed_after_its_publisher_appears_and_a_grace_period() -> None:
    run = Run(respawn=1)
    run.start()
    run.tick(simulator_state="running")
    out = run.kill(SIM, 10)
    assert out[-1] == Restart(SIM) and run.sup.resume_pending and run.sup.restarts == {SIM: 1}
    # the dead simulator's state ("finished" would not end the run while the new one waits)
    assert run.tick(simulator_state="finished") == [] and run.sup.phase is Phase.RUNNING
    assert run.tick(2.0) == []  # no new publisher yet: wait
    assert run.tick(rod_state_publishers=frozenset({"sim0", "sim1"})) == []  # discovered: grace period
    assert run.tick(0.5) == []
    assert run.tick(0.6) == [Resume()]
    assert run.tick(1.0) == []  # no answer yet (the old resume's answer does not count)
    assert run.tick(1.1) == [Resume()]  # resent after 2 s without an answer
    assert run.tick(resume_answered=False) == []
    assert run.tick(resume_answered=True) == [Notify("resumed", {"restart": True})]
    assert not run.sup.resume_pending
    assert run.tick(simulator_state="running") == []
    assert run.finish() == [Finish(None)]


def test_resume_waits_for_the_pause_service() -> None:
    run = Run(respawn=1)
    run.start()
    run.kill(SIM, 10)
    run.tick(pause_ready=False, rod_state_publishers=frozenset({"sim1"}))
    assert run.tick(1.5) == []
    assert run.tick(pause_ready=True) == [Resume()]


def test_simulator_dying_again_beyond_respawn_ends_the_run() -> None:
    run = Run(respawn=1)
    run.start()
    run.kill(SIM, 10)
    assert run.kill(SIM, 30)[-1] == Finish("node 'rod_simulator' exited with code -9")
    assert run.sup.faults == [{"node": SIM, "exit_code": -9, "action": "restarted"}]


def test_simulator_restarted_before_the_start_is_resumed_again_after_it() -> None:
    """A restart while connecting: the first resume starts it; the pending restart resume is
    then sent once more (harmless to a running simulator) and the run ends normally."""
    run = Run(respawn=1)
    out = run.kill(SIM, 10, 1)
    assert out[-1] == Restart(SIM) and run.sup.phase is Phase.CONNECTING
    run.start()
    run.tick(rod_state_publishers=frozenset({"sim1"}), simulator_state="finished")
    assert run.sup.phase is Phase.RUNNING  # not finished while the restart resume is pending
    assert run.tick(1.1) == [Resume()]
    assert run.tick(resume_answered=True) == [Notify("resumed", {"restart": True})]
    assert run.finish() == [Finish(None)]


def test_several_exits_in_one_tick_are_handled_in_order_until_one_ends_the_run() -> None:
    run = Run(respawn=0, recording=True)
    run.start()
    out = run.tick(exited=(Exit(REC, 20, 1), Exit(SIM, 10, -9), Exit(SENSOR, 11, -9)))
    assert [e[1]["node"] for e in events(out)] == [REC, SIM]
    assert out[-1] == Finish("node 'rod_simulator' exited with code -9")


def test_interrupted() -> None:
    run = Run()
    run.start()
    run.sup.interrupted()
    assert run.sup.done and run.sup.error == "interrupted"
    run.sup.interrupted()
    assert run.sup.error == "interrupted"


@pytest.mark.parametrize("phase", ["connecting", "running", "settling"])
def test_another_graphs_simulator_in_the_domain_ends_the_run_in_any_phase(phase: str) -> None:
    """A node of the graph that this launcher did not start, heard on its namespace's status: the
    two graphs' messages mix (each controller answers both simulators), so the run fails, whatever
    its phase."""
    run = Run()
    if phase != "connecting":
        run.start()
    if phase == "settling":
        assert run.tick(simulator_state="finished") == [] and run.sup.phase is Phase.SETTLING
    out = run.tick(foreign=("grasp_controller", 4242))
    assert len(out) == 1 and isinstance(out[0], Finish) and out[0].error is not None
    assert out[0].error.startswith("another graph's grasp_controller (pid 4242) runs in this domain and namespace")
    assert "--namespace or --domain-id" in out[0].error and run.sup.done and run.sup.error == out[0].error
    assert run.tick(foreign=("grasp_controller", 4242)) == []  # (once)
