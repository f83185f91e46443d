"""Rod obstacle/sensing, the closed-loop paper scenario (Sec. V-C) and the simulate subcommand."""

from __future__ import annotations

import argparse
import json

from dataclasses import replace

import numpy as np
import pytest

from contgrasp_core.arm import ArmShape
from contgrasp_core.boundary import circle, deformed_circle, ellipse
from contgrasp_core.contact import sense
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.rod import Obstacle, RodSystem, chain
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop
from contgrasp_core.control import paper_gains
from contgrasp_core.scenario import PAPER

_wrap = lambda a: np.mod(a + np.pi, 2 * np.pi) - np.pi  # noqa: E731


@pytest.mark.parametrize("b", [circle(0.025, (0.08, 0.08)), ellipse(0.03, 0.018, (0.08, 0.07), 0.3),
                               deformed_circle(0.025, center=(0.08, 0.08))], ids=["circle", "ellipse", "deformed"])
def test_obstacle_projection_matches_boundary_project(b):
    rng = np.random.default_rng(0)
    q = np.array([0.08, 0.08]) + rng.uniform(-0.06, 0.06, size=(200, 2))
    q = q[np.hypot(*(q - [0.08, 0.08]).T) > 0.005]
    ref = b.project(q)
    got = Obstacle(b).project(q)
    np.testing.assert_allclose(got.foot, ref.foot, atol=1e-8)
    np.testing.assert_allclose(got.signed_distance, ref.signed_distance, atol=1e-8)
    np.testing.assert_allclose(_wrap(got.phi - b.tangent_angle(ref.s_o)), 0.0, atol=1e-6)


@pytest.mark.parametrize("b", [PAPER.object.boundary(), ellipse(0.03, 0.018, (0.08, 0.07), 0.3),
                               deformed_circle(0.025, center=(0.08, 0.08))], ids=["circle", "ellipse", "deformed"])
def test_rod_sensing_with_the_obstacle_matches_the_boundary(b):
    """The rod's sensing (``sense`` with the fast Obstacle projection, at the nodes of
    ``chain.arm_shape``) gives the library's contact state (``sense`` with Boundary.project)."""
    m = replace(PAPER.rod, n_elements=40)
    theta = np.linspace(0.0, 2.5, 40)
    shape = chain.arm_shape(m, theta)
    assert isinstance(shape, ArmShape)
    np.testing.assert_array_equal(shape.r, chain.nodes(m, theta))
    np.testing.assert_array_equal(shape.theta, chain.node_angles(m, theta))
    fast = sense(shape, Obstacle(b), m.radius(m.s_nodes))
    exact = sense(shape, b, m.radius(m.s_nodes))
    for name in ("rho", "delta", "s_o", "foot"):
        np.testing.assert_allclose(getattr(fast, name), getattr(exact, name), atol=1e-8, err_msg=name)
    # angles: one Newton step on the osculating circle leaves ~1e-8 rad (cf. the projection test)
    np.testing.assert_allclose(fast.normal_out, exact.normal_out, atol=1e-6)
    np.testing.assert_allclose(_wrap(fast.alpha - exact.alpha), 0.0, atol=1e-6)
    # the Obstacle's kappa_o is the curvature at the nearest table sample, not at the foot
    np.testing.assert_allclose(fast.foot_turn, exact.foot_turn, rtol=1e-2)
    np.testing.assert_array_equal(fast.valid, exact.valid)


@pytest.fixture(scope="module")
def paper_run():
    m = PAPER.rod
    system = RodSystem(m, Obstacle(PAPER.object.boundary()))
    return run_closed_loop(system, paper_gains(m, 0.025), ClosedLoopConfig(duration=6.0, dt=0.01, record_period=0.01))


def test_paper_scenario_grasps_and_settles(paper_run):
    res, m = paper_run, paper_run.model
    assert res.settled and res.settle_time < 6.0
    r = m.radius(m.s_nodes)
    rho, alpha = res.rho[-1], res.alpha[-1]
    # the arm wraps the circle: the distal half hugs it within a few local radii, parallel to it
    distal = m.s_nodes > 0.11
    assert np.all(rho[distal] < 1.6 * r[distal])
    assert np.all(np.abs(alpha[distal] - np.pi / 2) < 0.1)
    # tip angle around the object centre: it curled past the top of the circle
    d = res.x[-1][-1] - np.array([0.08, 0.08])
    assert np.arctan2(d[1], d[0]) > np.pi / 3
    # contact region: rho/rho_d close to 1, alpha close to but below pi/2 (taper)
    contact = rho <= 1.5 * r
    assert np.mean(np.abs(rho[contact] / r[contact] - 1)) < 0.2
    assert -0.1 < np.mean(alpha[contact] - np.pi / 2) < 0.0
    # settled penetration below 1 % of the local radius
    assert res.penetration_ratio[-1] < 0.01


def test_paper_scenario_matches_static_theory_where_unobstructed(paper_run):
    from contgrasp_core.rod.closed_loop import static_solution

    res, m = paper_run, paper_run.model
    s, rho_th, alpha_th = static_solution(res, 0.025)
    r = m.radius(s)
    # eq. (8) + eq. (20) from the base: the rod follows it up to where the
    # static solution would cut into the object (paper: "arm not being able to pass through the
    # object"); the contact reaction loads the proximal rod too, so agreement there is approximate
    free = s < s[np.argmax(rho_th < r)] - 0.01
    assert free.sum() > 30
    np.testing.assert_allclose(res.alpha[-1][free], alpha_th[free], atol=0.12)
    np.testing.assert_allclose(res.rho[-1][free], rho_th[free], rtol=0.15)
    # and far from the contact, near the base, closely
    near = (s >= 0.01) & (s < 0.03)
    np.testing.assert_allclose(res.alpha[-1][near], alpha_th[near], atol=0.04)


def test_sampled_feedback_agrees_with_continuous_over_short_horizon():
    m = replace(PAPER.rod, n_elements=40)
    system = RodSystem(m, Obstacle(PAPER.object.boundary()))
    g = paper_gains(m, 0.025)
    cont = run_closed_loop(system, g, ClosedLoopConfig(duration=0.02, dt=5e-4, min_time=1.0))
    zoh = run_closed_loop(system, g, ClosedLoopConfig(duration=0.02, control_period=5e-4, min_time=1.0))
    assert cont.t[-1] == pytest.approx(zoh.t[-1])
    diff = np.hypot(*(cont.x[-1] - zoh.x[-1]).T).max()
    moved = np.hypot(*(cont.x[-1] - cont.x[0]).T).max()
    assert moved > 1e-3 and diff < 0.1 * moved


def test_closed_loop_rejects_bad_config():
    with pytest.raises(InvalidParameterError):
        ClosedLoopConfig(duration=-1.0)
    with pytest.raises(InvalidParameterError):
        ClosedLoopConfig(control_period=0.01, dt=0.003)
    with pytest.raises(InvalidParameterError):
        run_closed_loop(RodSystem(replace(PAPER.rod, n_elements=10)), paper_gains(replace(PAPER.rod, n_elements=10), 0.025))


def test_simulate_subcommand_json_and_plot(tmp_path):
    from contgrasp_core.cli import simulate as cli_simulate

    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers()
    cli_simulate.add_parser(sub)
    png = tmp_path / "fig4.png"
    args = ap.parse_args(["simulate", "--duration", "0.2", "--plot", str(png)])
    out = args.func(args)
    for key in ("final", "settled", "settle_time_s", "sim_time_s", "wall_time_s", "max_penetration",
                "mean_abs_rho_ratio_minus_1_contact", "mean_abs_alpha_minus_half_pi_contact"):
        assert key in out
    assert set(out["final"]) >= {"x", "y", "theta", "rho", "alpha"}
    assert len(out["final"]["x"]) == 101
    assert out["sim_time_s"] == pytest.approx(0.2)
    assert png.stat().st_size > 10_000
    with pytest.raises(InvalidParameterError):
        args.func(ap.parse_args(["simulate", "--object", "square"]))


def test_held_expansion_is_the_law_to_first_order() -> None:
    """The couple held to first order in the state differs from the law evaluated at the new
    state by O(|dtheta|^2) (halving the perturbation quarters the error)."""
    import numpy as np

    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig
    from contgrasp_core.control import paper_gains
    from contgrasp_core.scenario import PAPER
    from contgrasp_core.rod.session import LoopSession
    from contgrasp_core.control import feedback_at_joints, HeldExpansion

    model, obj = replace(PAPER.rod, n_elements=30), PAPER.object.boundary()
    system = RodSystem(model, Obstacle(obj))
    gains = paper_gains(model, 0.025)
    session = LoopSession(system, ClosedLoopConfig(duration=1.0, control_period=0.002))
    theta0 = session.state.theta + 0.3 * np.sin(np.linspace(0, 3, model.n_elements))
    session.state = type(session.state)(t=0.0, theta=theta0, omega=session.state.omega)

    def law(theta):  # type: ignore[no-untyped-def]
        session.state = type(session.state)(t=0.0, theta=theta, omega=session.state.omega)
        session._observed = None
        obs = session.observe()
        c = sense(obs.shape, obj, obs.radius)
        return feedback_at_joints(model, gains, c.rho, c.alpha)

    e = law(theta0)
    held = HeldExpansion(model, system.obstacle, e)
    du0, _ = held.couple_and_jacobian(theta0, jacobian=False)
    np.testing.assert_allclose(du0, 0.0, atol=1e-12 * np.max(np.abs(e.u)))
    direction = np.cos(np.linspace(0, 5, model.n_elements))
    errs = []
    for eps in (1e-2, 5e-3, 2.5e-3):
        th = theta0 + eps * direction
        du, _ = held.couple_and_jacobian(th, jacobian=False)
        errs.append(np.max(np.abs(law(th).u - (e.u + du))))
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all(ratios > 3.5), ratios


def test_preload_leaves_the_system_as_it_was() -> None:
    """The simulator loads its kernels by stepping throwaway sessions on the run's own system
    (:func:`~contgrasp_core.rod.session.preload`): the run that follows on that system must be
    the run without the preload, bit for bit (a step must not keep anything of the states it saw)."""
    from contgrasp_core.rod.session import preload, run_sampled
    from contgrasp_core.scenario import PAPER

    scenario = replace(PAPER, loop=replace(PAPER.loop, duration=0.02))
    fresh = run_sampled(scenario).observe()
    system = scenario.system()
    preload(system, scenario.loop)
    preloaded = run_sampled(scenario, system).observe()
    assert fresh.k == preloaded.k == 10
    np.testing.assert_array_equal(preloaded.x, fresh.x)
    np.testing.assert_array_equal(preloaded.v, fresh.v)


def test_the_settle_detector_judges_the_latest_state() -> None:
    """Settled means quiet for ``settle_hold`` at the latest state: a rod that moves again is no
    longer settled, and ``settle_time`` is the start of the quiet stretch it is in."""
    from contgrasp_core.rod.closed_loop import SettleDetector

    det = SettleDetector(settle_speed=1e-3, settle_hold=0.3, min_time=1.0)
    for t in np.arange(0.0, 1.25, 0.05):
        det.update(float(t), 0.0)
    assert det.settled and det.settle_time == 0.0
    assert not det.update(1.25, 1.0) and det.settle_time is None  # (moved again)
    assert not det.update(1.3, 0.0) and not det.update(1.55, 0.0)  # (quiet, not yet for 0.3 s)
    assert det.update(1.6, 0.0) and det.settle_time == 1.3
    assert not det.update(1.65, 0.0, ready=False)  # (a law in transition is never quiet)


@pytest.mark.parametrize("mode", ["fixed", "free"])
def test_a_movable_object_is_watched_for_the_whole_duration(mode: str) -> None:
    """Under a settle rule that holds at once, the core loop and the graph's LoopSession
    (run_sampled) both stop a fixed object's run once settled, but take a movable object's run
    to its duration, settled at its end since it came to rest."""
    from contgrasp_core.rod.body import ObjectDynamics
    from contgrasp_core.rod.session import run_sampled

    loop = replace(PAPER.loop, duration=0.02, settle_speed=1e3, settle_hold=0.004, min_time=0.0)
    scenario = replace(PAPER, rod=replace(PAPER.rod, n_elements=20), dynamics=ObjectDynamics(mode), loop=loop)
    session = run_sampled(scenario)
    core = run_closed_loop(scenario.system(), scenario.feedback_gains, loop)
    expected = 2 if mode == "fixed" else 10  # (control periods of 2 ms: quiet from 0 for 4 ms, or all 20 ms)
    assert session.k == core.steps == expected
    assert session.settled and core.settled and session.settle_time == core.settle_time == 0.0


@pytest.mark.heavy
def test_simulate_watches_a_held_movable_object_until_the_duration(capsys: pytest.CaptureFixture[str]) -> None:
    """``contgrasp simulate --object-mode spring --law reactive --duration 4``: the hold comes to rest
    before 3.5 s and the run goes on to 4 s (it once stopped there), settled at the end, in steps
    of 2 ms (a movable object's default: coarser steps damp its escape, docs/holding.md). (Free,
    the object escapes at that step: docs/holding.md, "Resolved in time".)"""
    from contgrasp_core.cli import main

    main(["simulate", "--json", "--nodes", "51", "--object-mode", "spring", "--law", "reactive", "--duration", "4"])
    out = json.loads(capsys.readouterr().out)
    assert out["steps"] == 2000 and out["sim_time_s"] == pytest.approx(4.0) and out["control"] == "continuous, steps <= 0.002 s"
    assert out["settled"] and out["settle_time_s"] < 3.5 and out["law_phase"] == "hold"

def test_a_movable_object_is_stepped_at_the_graphs_period_unless_told() -> None:
    """``simulate``'s continuous loop: steps of up to 10 ms with the paper's fixed object, 2 ms with
    a movable one (the graph's control period; docs/holding.md, "Resolved in time"), ``--dt`` as
    given when given; a sampled loop takes its control period."""
    from contgrasp_core.cli import simulate

    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers()
    simulate.add_parser(sub)
    cfg = lambda *a: simulate.loop_config(ap.parse_args(["simulate", *a]))  # noqa: E731
    assert cfg().dt == simulate.FIXED_DT == 0.01
    assert cfg("--object-mode", "free").dt == cfg("--object-mode", "spring").dt == PAPER.loop.control_period == 0.002
    assert cfg("--object-mode", "free", "--dt", "0.005").dt == 0.005
    assert cfg("--control-period", "0.002").dt is None
