"""The commands that run a closed loop build one ``Scenario`` from their arguments and run it
through the core: ``simulate`` (``cli.simulate.scenario_from_args``), ``hold``
(``cli.hold.scenario_from_args``) and ``holding-study`` (``cli.holding_study.spec_from_args``,
each pose's ``holding.study.pose_scenario``). Each is the scenario the ROS graph builds from the
equivalent parameters (``Scenario.from_ros_parameters``), and ``simulate``'s sampled loop is
``run_sampled`` of its scenario, bit for bit (docs/design.md, "One scenario model")."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from contgrasp_core.cli import build_parser, main
from contgrasp_core.scenario import Scenario


def _graph(params: dict[str, dict[str, Any]]) -> Scenario:
    """The graph's scenario of ``params``, its gains' object radius the object's own (the
    parameters name it; a command's scenario takes it from the object, the same number)."""
    graph = Scenario.from_ros_parameters(params)
    return graph.with_object(graph.object)


@pytest.mark.parametrize("argv,params", [
    (["--law", "reactive", "--object-mode", "free", "--control-period", "0.002", "--hold", "first-order", "--nodes", "51",
      "--friction", "0.3", "--duration", "0.5", "--max-muscle-stress", "2e4", "--contact-tol", "0.001", "--depth-gain", "5"],
     {"/**": {"n_elements": 50, "friction": 0.3, "friction_model": "stick", "max_muscle_stress": 2e4},
      "rod_simulator": {"duration": 0.5, "control_period": 0.002, "object_mode": "free"},
      "grasp_controller": {"law": "reactive", "hold_depth_gain": 5.0}, "boundary_sensor": {"contact_tolerance": 0.001}}),
    # the continuous loop: a movable object's steps of 2 ms, a fixed object's 10 ms (the scenario's loop dt)
    (["--object-mode", "spring", "--law", "reactive", "--duration", "0.5"],
     {"rod_simulator": {"duration": 0.5, "control_period": 0.0, "dt": 0.002, "object_mode": "spring",
                        "object_stiffness": [50.0, 50.0, 0.05], "object_damping": [1.0, 1.0, 0.001]},
      "grasp_controller": {"law": "reactive"}}),
    (["--object", "ellipse", "--damping", "2"],
     {"/**": {"damping": 2.0}, "rod_simulator": {"object": "ellipse:0.03,0.02", "control_period": 0.0, "dt": 0.01}}),
])
def test_simulates_scenario_is_the_graphs(argv: list[str], params: dict[str, dict[str, Any]]) -> None:
    from contgrasp_core.cli import simulate

    assert simulate.scenario_from_args(build_parser().parse_args(["simulate", *argv])) == _graph(params)


def test_holds_scenario_is_the_graphs() -> None:
    from contgrasp_core.cli import hold

    args = build_parser().parse_args(["hold", "--law", "reactive", "--nodes", "51", "--base", "0.01", "0.0", "0.1",
                                      "--max-muscle-stress", "1e4", "--clearance", "0.004"])
    assert hold.scenario_from_args(args) == _graph(
        {"/**": {"n_elements": 50, "base_x": 0.01, "base_y": 0.0, "base_angle": 0.1, "max_muscle_stress": 1e4},
         "grasp_controller": {"law": "reactive", "hold_clearance": 0.004}})


def test_a_study_poses_scenario_is_the_graphs(tmp_path: Any) -> None:
    """The rod's arm at a pose 10 paper units (5 cm) left of the object's centre, heading 1.5 rad."""
    from contgrasp_core.cli import holding_study
    from contgrasp_core.holding.study import pose_scenario

    args = build_parser().parse_args(["holding-study", "--arm", "rod", "--nodes", "21", "--duration", "3", "--law", "reactive",
                                      "--dwell", "0.05", "--out", str(tmp_path / "s.jsonl")])
    pose = pose_scenario(holding_study.spec_from_args(args), (-10.0, 0.0, 1.5))
    assert pose == _graph({"/**": {"n_elements": 20, "base_x": 0.03, "base_y": 0.08, "base_angle": 1.5},
                           "rod_simulator": {"duration": 3.0}, "grasp_controller": {"law": "reactive", "hold_dwell": 0.05}})


@pytest.mark.heavy
@pytest.mark.parametrize("argv", [
    ["--control-period", "0.002", "--hold", "first-order", "--duration", "0.3", "--nodes", "51"],
    ["--law", "reactive", "--object-mode", "free", "--control-period", "0.002", "--hold", "first-order", "--duration", "0.5",
     "--nodes", "51"],
])
def test_the_sampled_simulate_is_run_sampled_bit_for_bit(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """``simulate --hold first-order`` is the graph's loop: it ends where ``run_sampled`` of its
    scenario ends, to the bit (state, steps, settling, the law's phase, the object's motion)."""
    from contgrasp_core.cli import simulate
    from contgrasp_core.rod.session import run_sampled

    scenario = simulate.scenario_from_args(build_parser().parse_args(["simulate", *argv]))
    law = scenario.controller()
    session = run_sampled(scenario, law=law)
    last = session.observe()
    assert main(["simulate", "--json", *argv]) in (0, None)
    out = json.loads(capsys.readouterr().out)
    final = out["final"]
    assert final["x"] == last.x[:, 0].tolist() and final["y"] == last.x[:, 1].tolist()
    assert final["theta"] == last.theta.tolist()
    assert (out["steps"], out["sim_time_s"], out["settled"], out["settle_time_s"]) == (
        session.k, last.t, session.settled, session.settle_time)
    assert out["newton_iterations"] == session.iterations and out["max_penetration"] == session.max_penetration
    assert out["law_phase"] == getattr(law, "phase", None)
    if last.body is not None:
        assert [out["object_displacement"][k] for k in ("x", "y", "angle")] == last.body.q.tolist()


def test_the_recorded_sampled_loop_is_the_sampled_loop() -> None:
    """``record_sampled`` records ``run_sampled``'s steps: every state it records is one the
    unrecorded loop passed through (its last the final state), and its largest penetration
    ratio is the run's validity's."""
    from dataclasses import replace

    from contgrasp_core.rod.session import record_sampled, run_sampled
    from contgrasp_core.scenario import PAPER

    scenario = replace(PAPER, rod=replace(PAPER.rod, n_elements=40), loop=replace(PAPER.loop, duration=0.2))
    seen: list[np.ndarray] = []
    run_sampled(scenario, record=lambda session, obs, contact, answer: seen.append(obs.theta))
    res = record_sampled(scenario, 0.01)
    assert len(res.t) == 21 and len(seen) == 101
    for k, theta in zip(range(0, 101, 5), res.theta, strict=True):
        np.testing.assert_array_equal(theta, seen[k])
    assert res.health is not None and res.max_penetration_ratio == res.health.validity()["max_penetration_ratio"]
