"""The planned hold, law ``hold`` (docs/holding.md, "A planned path of held shapes holds it"):
the plan (the holding law on the fixed object), its playback as held shapes, its settings and
parameters, and the free circle kept through the sampled loop."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.control.hold_law import LAWS, HoldLawSettings, ShapeHold, check_law_settings
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.holding import plan as plan_module
from contgrasp_core.holding.experiment import GraspFailure, HoldExperiment, HoldSettings
from contgrasp_core.holding.measure import check_reach
from contgrasp_core.holding.plan import HoldPlan, PlannedHold, balanced_forces, plan_hold
from contgrasp_core.objects import ROD_SCALE, ObjectSpec
from contgrasp_core.rod import chain
from contgrasp_core.rod.body import ObjectDynamics
from contgrasp_core.rod.closed_loop import run_closed_loop
from contgrasp_core.rod.model import RodModel
from contgrasp_core.scenario import PAPER, Scenario

PLAN = replace(PAPER, law="hold")
GRIP = replace(PLAN, rod=replace(PLAN.rod, friction=0.5, friction_model="stick"))
"""The paper's scenario under the planned hold with friction (mu = 0.5): the plan squeezes (P2)."""


@pytest.fixture(scope="module")
def paper_plan() -> HoldPlan:
    return plan_hold(PLAN)


@pytest.fixture(scope="module")
def grip_plan() -> HoldPlan:
    return plan_hold(GRIP)


def test_the_plan_is_the_holding_law_on_the_fixed_object_to_its_hold(paper_plan: HoldPlan) -> None:
    """The plan records the holding law's run on the fixed circle (the same loop run by hand) at
    every step (at most 2 ms), to its settled hold."""
    planner = replace(PAPER, law="reactive")
    law = planner.controller()
    res = run_closed_loop(planner.system(), planner.feedback_gains, plan_module.PLAN_LOOP, law=law)
    assert law.holding and res.settled
    want = np.array([PAPER.rod.joint_curvature(chain.element_angles(th)) for th in res.theta])
    np.testing.assert_array_equal(paper_plan.t, res.t)
    np.testing.assert_array_equal(paper_plan.kappa, want)
    assert paper_plan.t[0] == 0.0 and np.allclose(np.diff(paper_plan.t), plan_module.PLAN_LOOP.dt) and 2.0 < paper_plan.end < 20.0


def test_the_playback_commands_the_plan_interpolated_then_its_last_shape(paper_plan: HoldPlan) -> None:
    """The law's command is the held shape (H4) at the plan's curvature at the law's own time: a
    recorded time exactly, halfway between two linearly, and the last shape after the end; the
    phase is ``plan`` until the end, then ``hold``."""
    law = PlannedHold(PAPER.rod, paper_plan, replace(HoldLawSettings(), plan_damping=0.0))
    n = PAPER.rod.n_elements
    z = np.zeros(n + 1)
    assert law.name == "hold" and law.phase == "plan" and not law.holding
    first = law.command(z, z, z, z[:-1], 0.05)  # (t = 0)
    assert isinstance(first, ShapeHold) and first.gain == 100.0
    np.testing.assert_array_equal(first.kappa_ref, paper_plan.kappa[0])
    np.testing.assert_array_equal(first.couple, -PAPER.rod.joint_ei * paper_plan.kappa[0])
    law.t = float(paper_plan.t[37])
    np.testing.assert_array_equal(law.command(z, z, z, z[:-1], 0.002).kappa_ref, paper_plan.kappa[37])
    law.t = 0.5 * float(paper_plan.t[40] + paper_plan.t[41])
    np.testing.assert_allclose(law.command(z, z, z, z[:-1], 0.002).kappa_ref,
                               0.5 * (paper_plan.kappa[40] + paper_plan.kappa[41]), rtol=1e-12, atol=1e-12)
    assert law.t == pytest.approx(0.5 * float(paper_plan.t[40] + paper_plan.t[41]) + 0.002)
    law.t = paper_plan.end + 1.0
    assert law.holding and law.phase == "hold" and paper_plan.squeeze is None  # (frictionless: no squeeze)
    np.testing.assert_array_equal(law.command(z, z, z, z[:-1], 0.002).kappa_ref, paper_plan.kappa[-1])


@pytest.mark.heavy
def test_with_friction_the_squeeze_ramps_in_after_the_plan(grip_plan: HoldPlan) -> None:
    """(P2): after the plan's end the held shape is the last one less ``C / ((1 + G) EI)``,
    ramped in linearly over ``plan_squeeze_time``; before the end, the plan as without it."""
    sq = grip_plan.squeeze
    assert sq is not None
    law = PlannedHold(GRIP.rod, grip_plan, replace(HoldLawSettings(), plan_damping=0.0))
    z = np.zeros(GRIP.rod.n_elements + 1)
    squeezed = grip_plan.kappa[-1] - sq.couple / (101.0 * GRIP.rod.joint_ei)
    law.t = grip_plan.end + 1.0
    np.testing.assert_allclose(law.command(z, z, z, z[:-1], 0.002).kappa_ref, squeezed, rtol=1e-12, atol=1e-12)
    law.t = grip_plan.end + 0.1  # (a third of the 0.3 s ramp)
    np.testing.assert_allclose(law.command(z, z, z, z[:-1], 0.002).kappa_ref,
                               grip_plan.kappa[-1] + (squeezed - grip_plan.kappa[-1]) / 3.0, rtol=1e-9, atol=1e-9)
    law.t = float(grip_plan.t[-2])
    np.testing.assert_array_equal(law.command(z, z, z, z[:-1], 0.002).kappa_ref, grip_plan.kappa[-2])


def test_balanced_forces_closed_forms() -> None:
    """(P2)'s programme on normals whose answer is known: three at 120 degrees about a point
    all at their caps; two opposed at the smaller cap; a pure couple (opposed, offset) and
    normals within a half-plane balance only at zero."""
    a = np.radians([90.0, 210.0, 330.0])
    pts = np.stack([np.cos(a), np.sin(a)], axis=1)
    np.testing.assert_allclose(balanced_forces(pts, -pts, np.ones(3)), np.ones(3), atol=1e-9)
    pts2, n2 = np.array([[-1.0, 0.0], [1.0, 0.0]]), np.array([[1.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_allclose(balanced_forces(pts2, n2, np.array([1.0, 2.0])), [1.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(balanced_forces(np.array([[0.0, 1.0], [0.0, -1.0]]), n2, np.ones(2)), 0.0, atol=1e-9)
    b = np.radians([200.0, 270.0, 340.0])  # (contact points on the lower half: the normals all point up)
    lower = np.stack([np.cos(b), np.sin(b)], axis=1)
    np.testing.assert_allclose(balanced_forces(lower, -lower, np.ones(3)), 0.0, atol=1e-9)


def _last_angles(rod: RodModel, plan: HoldPlan) -> np.ndarray:
    """The element angles of the plan's last shape (its curvature integrated from the base)."""
    return np.asarray(np.cumsum(plan.kappa[-1] * rod.joint_len) + rod.base_angle, dtype=float)


@pytest.mark.heavy
@pytest.mark.parametrize("stress", [0.0, 50000.0])
def test_the_squeeze_is_balanced_within_the_contact_and_the_muscles(grip_plan: HoldPlan, stress: float) -> None:
    """The plan's squeeze (P2) on the paper's circle: no net force or torque on the object (at
    1e-9 of its total), every force within what presses its element in by ``plan_squeeze`` of the
    radius, a squeeze at all (the wrap spans more than a half-plane), and within 50 kPa muscles
    no joint's squeeze couple beyond half the headroom between the bound and its shape's couple."""
    scenario = replace(GRIP, rod=replace(GRIP.rod, max_muscle_stress=stress))
    plan = grip_plan if stress == 0 else plan_hold(scenario)
    sq = plan.squeeze
    assert sq is not None and sq.total > (0.01 if stress else 0.1)  # (measured: 0.30 N; 0.053 N, the muscles' limit)
    rod, boundary = scenario.rod, scenario.object.boundary()
    proj = boundary.project(chain.centres(rod, _last_angles(rod, plan)))
    inward = -proj.normal_out[sq.elements]
    net = sq.forces @ inward
    torque = sq.forces @ (proj.foot[sq.elements, 0] * inward[:, 1] - proj.foot[sq.elements, 1] * inward[:, 0])
    assert np.hypot(*net) < 1e-9 * sq.total and abs(torque) < 1e-9 * sq.total
    caps = HoldLawSettings().plan_squeeze * rod.r_centres[sq.elements] * rod.h * rod.contact_stiffness
    assert np.all(sq.forces <= caps * (1 + 1e-9)) and np.all(sq.forces >= -1e-12)
    if stress:
        assert rod.muscle_bound is not None
        elastic = rod.joint_ei * rod.joint_curvature(_last_angles(rod, plan))
        room = 0.5 * np.maximum(rod.muscle_bound - np.abs(elastic), 0.0)
        assert np.all(np.abs(sq.couple) <= room * (1 + 1e-9) + 1e-15)


def test_the_plans_close_is_when_the_planners_cage_closed(paper_plan: HoldPlan) -> None:
    """``close`` is the law's time of the first command given in the phase ``close`` (watched
    from outside the law), within the plan."""
    planner = replace(PAPER, law="reactive")
    law = planner.controller()
    seen: list[float] = []
    command, clock = law.command, [0.0]

    def watched(*args: object) -> object:
        out = command(*args)  # type: ignore[arg-type]
        if law.phase == "close" and not seen:
            seen.append(clock[0])
        clock[0] += float(args[-1])  # type: ignore[arg-type]
        return out

    law.command = watched  # type: ignore[method-assign]
    run_closed_loop(planner.system(), planner.feedback_gains, plan_module.PLAN_LOOP, law=law)
    assert seen and paper_plan.close == pytest.approx(seen[0], abs=1e-12) and 0.0 < paper_plan.close < paper_plan.end


def test_the_damper_is_a_maxwell_element_on_the_deviation_from_the_close_on(paper_plan: HoldPlan) -> None:
    """(P1): before the close the command is the held shape at G alone, whatever the deviation;
    from the close a deviation ``E`` held from a relaxed damper gives the couple
    ``-EI kp + G EI E + D EI E exp(-t / tau)`` (a spring D in series with a dashpot D tau: its
    step response), exactly at every period."""
    settings = HoldLawSettings(plan_damping=300.0, plan_damping_time=0.1)
    law = PlannedHold(PAPER.rod, paper_plan, settings)
    m, n, period = PAPER.rod, PAPER.rod.n_elements, 0.002
    z = np.zeros(n + 1)
    rng = np.random.default_rng(1)
    while law.t + period <= paper_plan.close:  # (deviations before the close: no damper, the damper relaxed to them)
        kp = paper_plan.at(law.t)
        out = law.command(z, z, z, kp + rng.normal(0.0, 5.0, n), period)
        assert out.gain == settings.plan_gain
        np.testing.assert_array_equal(out.kappa_ref, kp)
    law.t, law.xi = paper_plan.close, np.zeros(n)  # (relaxed at zero deviation at the close)
    step = rng.normal(0.0, 5.0, n)
    for k in range(40):
        kp = paper_plan.at(law.t)
        kappa = kp + step
        out = law.command(z, z, z, kappa, period)
        theta = np.cumsum(kappa * m.joint_len) + m.base_angle  # (the element angles whose curvature is kappa)
        u, _ = out.couple_and_jacobian(theta, jacobian=False)
        want = -m.joint_ei * kp + m.joint_ei * step * (settings.plan_gain + settings.plan_damping
                                                       * np.exp(-k * period / settings.plan_damping_time))
        np.testing.assert_allclose(out.couple + u, want, rtol=1e-9, atol=1e-12)


@pytest.mark.heavy
def test_the_scenario_builds_the_law_and_its_settings_travel() -> None:
    """``law hold`` is a law of the scenario: its controller is a fresh playback at ``plan_gain``;
    the hold settings apply to it (the playback's refused under the paper's law and the reactive
    one, which ignore them), the reach is checked (its planner is the reactive law),
    ``hold_plan_gain`` is a controller parameter that round trips, and a bad gain is refused in
    one line."""
    assert LAWS == ("paper", "hold", "reactive")
    s = replace(PLAN, hold_law=HoldLawSettings(plan_gain=300.0, squeeze=0.0006))
    law = s.controller()
    assert isinstance(law, PlannedHold) and law.gain == 300.0 and law.t == 0.0 and law.phase == "plan"
    assert law.damping == s.hold_law.plan_damping and law.damping_time == s.hold_law.plan_damping_time
    params = s.to_ros_parameters()
    assert params["grasp_controller"]["hold_plan_gain"] == 300.0 and params["grasp_controller"]["law"] == "hold"
    assert params["grasp_controller"]["hold_plan_damping"] == s.hold_law.plan_damping
    for name in ("object", "object_outline", "object_center", "object_angle"):  # (the controller plans on the object)
        assert params["grasp_controller"][name] == params["rod_simulator"][name]
    assert Scenario.from_ros_parameters(params) == s
    free = replace(s, dynamics=ObjectDynamics(mode="free"))
    assert Scenario.from_ros_parameters(free.to_ros_parameters()) == free
    check_law_settings("hold", HoldLawSettings(plan_gain=30.0))
    with pytest.raises(InvalidParameterError, match="nothing under law paper: it needs law hold$"):
        check_law_settings("paper", HoldLawSettings(plan_gain=30.0))
    with pytest.raises(InvalidParameterError, match="plan_damping does nothing under law reactive: it needs law hold$"):
        check_law_settings("reactive", HoldLawSettings(plan_damping=30.0, squeeze=0.001))  # (the squeeze is the planner's)
    with pytest.raises(InvalidParameterError, match="squeeze, plan_gain do nothing under law paper: they need law hold or reactive$"):
        check_law_settings("paper", HoldLawSettings(squeeze=0.001, plan_gain=30.0))
    for name, bad in (("plan_gain", -1.0), ("plan_gain", float("nan")), ("plan_damping", -1.0),
                      ("plan_damping_time", 0.0), ("plan_damping_time", float("inf"))):
        with pytest.raises(InvalidParameterError, match=f"hold law {name}") as info:
            HoldLawSettings(**{name: bad})
        assert "\n" not in str(info.value)
    too_far = PLAN.with_object(ObjectSpec.parse("circle:0.035", ROD_SCALE))  # (its cage cannot close: docs/holding.md)
    with pytest.raises(InvalidParameterError, match="cannot close"):
        check_reach(too_far)


def test_a_planner_that_never_reaches_the_hold_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(plan_module, "PLAN_LOOP", replace(plan_module.PLAN_LOOP, duration=0.5))
    with pytest.raises(InvalidParameterError, match="no plan") as info:
        PLAN.controller()
    assert "\n" not in str(info.value)


def test_a_plan_whose_steps_shrink_is_refused_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan's loop refuses once its rod engine takes more Newton iterations per period than
    its limit (the paper's plan takes 2.5 per period; a limit of 1.5 trips it, counted from the
    100th period), in one line naming the count; a limit below 1 is refused."""
    monkeypatch.setattr(plan_module, "PLAN_LOOP", replace(plan_module.PLAN_LOOP, max_iterations_per_period=1.5))
    with pytest.raises(InvalidParameterError, match=r"no plan: .* could not be computed \(the rod engine took \d+ Newton "
                       r"iterations in \d+ steps for 100 control periods .* more than 1.5 per period") as info:
        PLAN.controller()
    assert "\n" not in str(info.value)
    with pytest.raises(InvalidParameterError, match="max_iterations_per_period must be finite and >= 1"):
        replace(plan_module.PLAN_LOOP, max_iterations_per_period=0.5)


@pytest.mark.heavy
@pytest.mark.parametrize(("stress", "friction"), [("0", "0"), ("50000", "0"), ("0", "0.5")])
def test_the_planned_hold_keeps_the_free_circle_through_the_sampled_loop(stress: str, friction: str) -> None:
    """``contgrasp simulate --law hold --object-mode free`` sampled at 2 ms and held to first
    order, as the graph runs it, at the default 4 s, unbounded and within 50 kPa muscles,
    frictionless and at mu = 0.5: the paper's circle settled within 5 mm and 0.2 rad of its
    start, slower than 1 mm/s, the arm outside it (valid), the law in its hold; with friction
    squeezing (P2), the thinnest pressed element in by ``plan_squeeze`` of its radius, as
    designed (measured 2026-11-28: settled at 2.838 s, 0.40 mm, 0.000 rad, 0.21 mm/s; 50 kPa:
    2.842 s, 0.21 mm, the base saturated; mu = 0.5: 3.266 s, 0.41 mm, 0.011 rad; without the
    damper, ``--plan-damping 0``, it rattles in the cage: 2.5 mm, 3.7 mm/s, not settled)."""
    proc = subprocess.run([sys.executable, "-m", "contgrasp_core.cli", "simulate", "--law", "hold", "--object-mode",
                           "free", "--control-period", "0.002", "--hold", "first-order", "--max-muscle-stress", stress,
                           "--friction", friction, "--json"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout)
    assert (out["peak_couple_ratio"] == pytest.approx(1.0)) if stress != "0" else out["peak_couple_ratio"] is None
    d, v = out["object_displacement"], out["object_velocity"]
    assert out["settled"] and out["sim_time_s"] == pytest.approx(4.0)
    assert np.hypot(d["x"], d["y"]) < 0.005 and abs(d["angle"]) < 0.2
    assert np.hypot(v["x"], v["y"]) < 0.001
    assert out["validity"]["valid"] and out["law"] == "hold" and out["law_phase"] == "hold"
    if friction != "0":
        assert out["final_penetration_ratio"] == pytest.approx(HoldLawSettings().plan_squeeze, abs=0.01)
    else:
        assert out["final_penetration_ratio"] < 0.01


@pytest.mark.heavy
def test_the_contact_wait_of_a_planned_hold_counts_from_its_close() -> None:
    """Within 50 kPa muscles the playback first comes within the cage's reach at 0.62 s, past the
    default 0.6 s without contact; the plan says when its arm reaches the object, so the wait
    counts from its close (0.372 s) and ``contgrasp hold --law hold --max-muscle-stress 50000``
    measures the grasp (before: "no node touched the object for 0.6 s")."""
    scenario = replace(PLAN, rod=replace(PLAN.rod, max_muscle_stress=5e4))
    short = HoldExperiment(scenario, HoldSettings(support=0, contact_wait=0.2))
    assert isinstance(short.law, PlannedHold) and short.law.plan.close == pytest.approx(0.372)
    with pytest.raises(GraspFailure, match=r"for 0.2 s \(at t = 0.572 s"):  # (the close plus the wait)
        short.grasp()
    default = HoldExperiment(scenario, HoldSettings(support=0))
    default.grasp()
    assert default.grasped is not None and default.grasped.settled and default.grasped.health.valid


def test_the_commands_take_law_plan_and_its_gain(tmp_path: Path) -> None:
    """``--law hold`` in simulate, hold, holding-study and the launcher (their choices are the
    laws); ``--plan-gain`` reaches the scenario as the controller's ``hold_plan_gain``, and is
    refused under the paper's law in one line."""
    from contgrasp_core.cli import build_parser, hold, holding_study, simulate
    from contgrasp_ros.launcher.cli import _parser

    parser = build_parser()
    args = parser.parse_args(["simulate", "--law", "hold", "--plan-gain", "300", "--object-mode", "free"])
    assert simulate.scenario_from_args(args) == Scenario.from_ros_parameters(
        {"grasp_controller": {"law": "hold", "hold_plan_gain": 300.0}, "rod_simulator": {"object_mode": "free",
                                                                                         "control_period": 0.0, "dt": 0.002}}
    ).with_object(PAPER.object)
    scenario = hold.scenario_from_args(parser.parse_args(["hold", "--law", "hold", "--plan-gain", "30"]))
    assert scenario.law == "hold" and scenario.hold_law.plan_gain == 30.0
    spec = holding_study.spec_from_args(parser.parse_args(["holding-study", "--arm", "rod", "--law", "hold", "--out",
                                                                 str(tmp_path / "s.jsonl")]))
    assert spec.law == "hold"
    assert _parser().parse_args(["--law", "hold"]).law == "hold"


def test_the_plan_gain_under_the_papers_law_is_refused_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from contgrasp_core.cli import main

    capsys.readouterr()
    assert main(["simulate", "--duration", "0.01", "--nodes", "11", "--plan-gain", "30"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "contgrasp simulate: error: --plan-gain does nothing under --law paper: it needs --law hold"]
    assert main(["simulate", "--duration", "0.01", "--nodes", "11", "--law", "hold", "--plan-gain", "-1"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "contgrasp simulate: error: hold law plan_gain must be >= 0, got -1.0"]


def test_a_launchs_object_reaches_the_controllers_copy() -> None:
    """``contgrasp-launch --object`` changes the simulator's object and the controller's copy
    (the plan's) alike."""
    from contgrasp_ros.launcher.graph import default_params_file, launch_overrides, load_params

    out = launch_overrides(load_params(default_params_file()), ObjectSpec.parse("ellipse", ROD_SCALE), law="hold")
    for name in ("object", "object_outline", "object_center", "object_angle"):
        assert out["grasp_controller"][name] == out["rod_simulator"][name]
    assert out["grasp_controller"]["object"].startswith("ellipse") and out["grasp_controller"]["law"] == "hold"
