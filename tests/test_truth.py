"""What a run reports is true and means one thing: one contact set per run, one settle
criterion, checked on the paper's run stepped with the core functions as the nodes step it."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contgrasp_core.control import feedback_at_joints
from contgrasp_core.rod import Obstacle, RodSystem
from contgrasp_core.contact import sense
from contgrasp_core.rod.session import LoopSession
from contgrasp_core.scenario import PAPER, QUALITY, SENSOR, Scenario
from contgrasp_core.tracking import contact_stats

REFERENCE = Path(__file__).parent / "golden" / "reference.json"


def stepped(scenario: Scenario) -> dict[str, Any]:
    """``session.run_sampled`` written out, keeping every node's speed at every step."""
    boundary = scenario.object.boundary()
    session = LoopSession(RodSystem(scenario.rod, Obstacle(boundary)), scenario.loop)
    t, speeds = [], []
    return _steps(session, boundary, scenario, t, speeds)


def _steps(session: LoopSession, boundary: Any, scenario: Scenario, t: list[float], speeds: list[Any]) -> dict[str, Any]:
    while True:
        obs = session.observe()
        t.append(obs.t)
        speeds.append(np.hypot(obs.v[:, 0], obs.v[:, 1]))
        c = sense(obs.shape, boundary, obs.radius, tol=scenario.sensing.contact_tolerance)
        if session.finished:
            return {"session": session, "obs": obs, "contact": c, "t": np.asarray(t), "speeds": np.asarray(speeds)}
        session.advance(feedback_at_joints(scenario.rod, scenario.feedback_gains, c.rho, c.alpha))


@pytest.fixture(scope="module")
def paper_run() -> dict[str, Any]:
    return stepped(PAPER)


def test_one_contact_tolerance_in_the_scenario() -> None:
    """The sensor flags contact with the scenario's one tolerance; the quality node has none of
    its own (it uses the contact states' flags and tolerance)."""
    params = PAPER.to_ros_parameters()
    assert params[SENSOR]["contact_tolerance"] == PAPER.sensing.contact_tolerance == 0.0005
    assert "contact_tolerance" not in params[QUALITY]
    assert not hasattr(PAPER.sensing, "quality_tolerance")


def test_the_contact_tolerance_does_not_steer_the_arm(paper_run: dict[str, Any]) -> None:
    """The law reads rho and alpha only, so the one 0.5 mm contact set leaves the trajectory of
    a zero tolerance (the reference run's) unchanged, bit for bit; and the reference numbers
    (computed before with a zero tolerance) are reproduced to their rounding."""
    zero = stepped(replace(PAPER, sensing=replace(PAPER.sensing, contact_tolerance=0.0)))
    s, obs = paper_run["session"], paper_run["obs"]
    assert s.k == zero["session"].k and s.settle_time == zero["session"].settle_time
    np.testing.assert_array_equal(obs.x, zero["obs"].x)
    np.testing.assert_array_equal(obs.theta, zero["obs"].theta)
    ref = json.loads(REFERENCE.read_text())["lockstep_paper_run"]
    assert s.k == ref["k"] and s.settle_time == pytest.approx(ref["settle_time"], abs=1e-12)
    np.testing.assert_allclose(obs.x, np.asarray(ref["x"]), rtol=0, atol=1e-12)


def test_the_headline_statistics_cover_the_grasp(paper_run: dict[str, Any]) -> None:
    """At the end of the paper run the arm wraps the circle over ~9 cm: the statistics say so
    (nodes and length) and give the tracking error as mean and max over that set."""
    c, obs = paper_run["contact"], paper_run["obs"]
    stats = contact_stats(obs.s, c.rho, c.delta, c.alpha, c.in_contact, c.tol)
    assert stats.contact_nodes is not None and stats.contact_nodes >= 40
    assert stats.contact_length is not None and 0.08 < stats.contact_length < 0.12
    assert stats.contact_nodes == int(np.count_nonzero(c.delta >= -PAPER.sensing.contact_tolerance))
    assert stats.mean_abs_rho_ratio_minus_1_contact is not None and stats.max_abs_rho_ratio_minus_1_contact is not None
    assert 0 < stats.mean_abs_rho_ratio_minus_1_contact <= stats.max_abs_rho_ratio_minus_1_contact
    assert stats.mean_abs_alpha_minus_half_pi_contact is not None and stats.max_abs_alpha_minus_half_pi_contact is not None
    assert 0 < stats.mean_abs_alpha_minus_half_pi_contact <= stats.max_abs_alpha_minus_half_pi_contact


def quiet_window_holds(t: np.ndarray, max_speed: np.ndarray, settle_time: float, speed: float, hold: float) -> None:
    """At ``settle_time`` every node is slower than ``speed`` and stays so for ``hold`` s, and
    the state before it was not quiet (the reported time is when the quiet began)."""
    i0 = int(np.flatnonzero(t == settle_time)[0])
    window = (t >= settle_time) & (t <= settle_time + hold + 1e-12)
    assert t[window][-1] >= settle_time + hold - 1e-9  # the window was observed to its end
    assert np.all(max_speed[window] < speed), max_speed[window].max()
    assert i0 > 0 and max_speed[i0 - 1] >= speed


def test_every_runner_uses_the_scenarios_settle_criterion() -> None:
    import argparse

    from contgrasp_core.cli import simulate

    ap = argparse.ArgumentParser()
    simulate.add_parser(ap.add_subparsers())
    cfg = simulate.loop_config(ap.parse_args(["simulate"]))
    for key in ("settle_speed", "settle_hold", "min_time", "duration"):
        assert getattr(cfg, key) == getattr(PAPER.loop, key), key
    assert (PAPER.loop.settle_speed, PAPER.loop.settle_hold) == (0.002, 0.3)
    params = PAPER.to_ros_parameters()["rod_simulator"]  # the simulator node's (and the YAML's)
    assert (params["settle_speed"], params["settle_hold"], params["min_time"]) == (0.002, 0.3, 1.0)


def test_the_graph_loop_settles_when_it_says(paper_run: dict[str, Any]) -> None:
    """The sampled loop the ROS graph runs: at the reported settle time every node is slower
    than settle_speed over the whole hold window (from every node's speed at every step)."""
    s = paper_run["session"]
    assert s.settled and s.settle_time is not None
    quiet_window_holds(paper_run["t"], paper_run["speeds"].max(axis=1), s.settle_time, PAPER.loop.settle_speed,
                       PAPER.loop.settle_hold)


def test_simulate_settles_when_it_says() -> None:
    """``contgrasp simulate`` (continuous feedback) by the same criterion, every step kept."""
    import argparse

    from contgrasp_core.cli import simulate
    from contgrasp_core.control import paper_gains
    from contgrasp_core.rod.closed_loop import run_closed_loop

    ap = argparse.ArgumentParser()
    simulate.add_parser(ap.add_subparsers())
    model = PAPER.rod
    res = run_closed_loop(RodSystem(model, Obstacle(PAPER.object.boundary())), paper_gains(model, PAPER.object.radius),
                          simulate.loop_config(ap.parse_args(["simulate"]), record_period=None))
    assert res.settled and res.settle_time is not None
    quiet_window_holds(res.t, res.max_speed, res.settle_time, PAPER.loop.settle_speed, PAPER.loop.settle_hold)
    out = simulate.summarize(res)
    assert out["settle_time_s"] == res.settle_time and out["contact_nodes"] >= 40


def test_the_shipped_sample_matches_the_code(paper_run: dict[str, Any]) -> None:
    """bags/paper_grasp.mcap is what the code makes today: the core loop run for the scenario
    the sample carries (its contgrasp_run record) ends at the recorded step and settle time in
    the recorded final state (to 1e-12: numba compiles the kernels for the host CPU, and another
    CPU's fused multiply-adds change the last bits; a 1e-17 m difference was seen between two
    machines of this kind). Regenerate it as bags/README.md says when not."""
    from contgrasp_core.rod.session import run_sampled
    from contgrasp_ros.recordings.run_data import load_run

    run = load_run(Path(__file__).resolve().parents[1] / "bags" / "paper_grasp.mcap")
    assert run.params is not None, "the sample carries no run parameters"
    scenario = Scenario.from_ros_parameters(run.params)
    if scenario == PAPER:
        session, obs = paper_run["session"], paper_run["obs"]
    else:  # pragma: no cover - a sample of another scenario
        session = run_sampled(scenario)
        obs = session.observe()
    assert int(run.status["step"]) == session.k == int(run.rod.step[-1]), "steps: regenerate the sample (bags/README.md)"
    assert float(run.status["settle_time_s"]) == session.settle_time, "settle time: regenerate the sample (bags/README.md)"
    assert float(run.status["sim_time_s"]) == obs.t
    np.testing.assert_allclose(run.rod.x[-1], obs.x[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.rod.y[-1], obs.x[:, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.rod.theta[-1], obs.theta, rtol=0, atol=1e-12)


@pytest.mark.heavy
def test_the_recipe_reproduces_the_shipped_sample(tmp_path: Path) -> None:
    """bags/README.md's command, run as written (its bash block, into a temporary folder), makes
    the shipped sample again: the same topics and message counts. /diagnostics
    is compared by presence only: the nodes' status timers run on the wall clock, so its count
    varies from run to run."""
    import os
    import re
    import subprocess
    import sys

    pytest.importorskip("contgrasp_msgs.msg")
    from conftest import fresh_domain_id

    from contgrasp_ros.bag.reader import info, open_recording

    root = Path(__file__).resolve().parents[1]
    blocks = re.findall(r"```bash\n(.*?)```", (root / "bags" / "README.md").read_text(), re.S)
    recipe = next(b for b in blocks if "contgrasp-launch --bag bags/paper_grasp.mcap" in b)
    script = recipe.replace("bags/paper_grasp", str(tmp_path / "paper_grasp"))
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
               ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.run(["bash", "-ec", script], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    made, shipped = (info(open_recording(p))["topics"] for p in (tmp_path / "paper_grasp.mcap", root / "bags" / "paper_grasp.mcap"))
    counts = [{t["name"]: t["count"] for t in topics} for topics in (made, shipped)]
    assert counts[0].keys() == counts[1].keys()
    assert {k: v for k, v in counts[0].items() if k != "/diagnostics"} == {
        k: v for k, v in counts[1].items() if k != "/diagnostics"}


def test_no_shipped_data_file_holds_a_path_of_the_machine_that_made_it() -> None:
    """The recordings, figures and test data carry no absolute path (the first sample's metadata
    named a worktree folder of the machine that recorded it)."""
    import re

    root = Path(__file__).resolve().parents[1]
    # (the usual homes and work folders; a bare drive letter would match inside compressed images)
    absolute = re.compile(rb"(/work/|/root/|/home/|/tmp/|/Users/|[A-Z]:\\\\Users\\\\)")
    files = [p for d in ("bags", "docs/figures", "tests/data") for p in (root / d).rglob("*")
             if p.is_file() and not any(part.startswith("run_") for part in p.parts)]  # (runs: git-ignored)
    assert any(p.suffix == ".mcap" for p in files)
    found = {str(p.relative_to(root)): m.group(0) for p in files if (m := absolute.search(p.read_bytes()))}
    assert not found
