"""``contgrasp simulate --json`` reports how many steps the run took and its wall time."""

from __future__ import annotations

import json

import pytest

from contgrasp_core.cli import main


@pytest.mark.parametrize("extra,periods", [(["--dt", "0.01"], 10), (["--control-period", "0.005"], 20),
                                           # the sampled loop held to first order, as the ROS graph steps it (it once reported 0 steps)
                                           (["--control-period", "0.005", "--hold", "first-order"], 20)])
def test_simulate_json_reports_steps_and_wall_time(capsys: pytest.CaptureFixture[str], extra: list[str],
                                                   periods: int) -> None:
    code = main(["simulate", "--json", "--duration", "0.1", "--nodes", "41", *extra])
    assert code in (0, None)
    out = json.loads(capsys.readouterr().out)
    assert out["steps"] == periods  # control periods advanced (continuous feedback: one per dt)
    assert out["integrator_steps"] >= out["steps"]  # accepted implicit steps, substeps included
    assert out["newton_iterations"] >= out["integrator_steps"]
    assert isinstance(out["wall_time_s"], float) and out["wall_time_s"] > 0.0


@pytest.mark.heavy
def test_the_first_order_loop_senses_a_free_object_where_it_is() -> None:
    """``simulate --hold first-order`` with a free object steps the loop as the ROS graph does:
    the arm sensed against the object where it is at each state (it once sensed the start pose:
    the law then chased an object that had gone). Its recorded run ends where run_sampled of the
    same scenario ends (which senses in the object's frame), bit for bit, after the object was pushed."""
    from dataclasses import replace

    import numpy as np

    from contgrasp_core.rod.body import ObjectDynamics
    from contgrasp_core.rod.session import record_sampled, run_sampled
    from contgrasp_core.scenario import PAPER

    scenario = replace(PAPER, rod=replace(PAPER.rod, n_elements=50), dynamics=ObjectDynamics("free"),
                       loop=replace(PAPER.loop, duration=0.8))
    core = run_sampled(scenario).observe()
    assert core.body is not None and np.hypot(*core.body.q[:2]) > 1e-3  # (the arm pushed the object)
    result = record_sampled(scenario, 0.01)
    np.testing.assert_array_equal(result.x[-1], core.x)
    assert result.object_q is not None
    np.testing.assert_array_equal(result.object_q[-1], core.body.q)


@pytest.mark.parametrize(("extra", "why"), [
    (["--control-period", "1e-9"], "control_period must be at least 0.0001 s"),
    (["--control-period", "5e-5", "--hold", "first-order"], "control_period must be at least 0.0001 s"),
    (["--dt", "1e-7"], "--duration 4 s at --dt 1e-07 s is 4e+07 steps, more than 1e+07"),
    (["--control-period", "1e-4", "--duration", "2000"], "--duration 2000 s at --control-period 0.0001 s is 2e+07 steps"),
])
def test_too_many_steps_are_refused_before_the_run(capsys: pytest.CaptureFixture[str], extra: list[str], why: str) -> None:
    """A tiny control period or step ran practically forever (``--control-period 1e-9``): the
    period has a floor (:data:`~contgrasp_core.rod.closed_loop.MIN_CONTROL_PERIOD`, the ROS nodes'
    ``control_period`` parameter's too) and a run at most 1e7 steps; exit 2 in one line."""
    from contgrasp_core.rod.closed_loop import MIN_CONTROL_PERIOD, ClosedLoopConfig

    assert main(["simulate", "--nodes", "21", *extra]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1 and why in err, err
    assert ClosedLoopConfig(control_period=5e-4).control_period == 5e-4 >= MIN_CONTROL_PERIOD  # (the tests' shortest)
