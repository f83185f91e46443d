"""What a run reports is true and means one thing (issue 19): one contact set per run, one settle
criterion, checked on the paper's run stepped with the core functions as the nodes step it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contgrasp_core.control import feedback_at_joints
from contgrasp_core.rod import Obstacle, RodSystem
from contgrasp_core.rod.session import LoopSession, sense_observation
from contgrasp_core.scenario import PAPER, QUALITY, SENSOR, Scenario
from contgrasp_core.tracking import contact_stats

REFERENCE = Path(__file__).parent / "golden" / "reference.json"


def stepped(scenario: Scenario) -> dict[str, Any]:
    """``session.run_sampled`` written out, keeping every node's speed at every step."""
    boundary = scenario.object.boundary()
    session = LoopSession(RodSystem(scenario.rod, Obstacle(boundary)), scenario.loop)
    t, speeds = [], []
    while True:
        obs = session.observe()
        t.append(obs.t)
        speeds.append(np.hypot(obs.v[:, 0], obs.v[:, 1]))
        c = sense_observation(obs, boundary, scenario.sensing.contact_tolerance)
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
    """The reference run was computed with a zero sensor tolerance; the law reads rho and alpha
    only, so the one 0.5 mm contact set leaves the trajectory unchanged, bit for bit."""
    ref = json.loads(REFERENCE.read_text())["lockstep_paper_run"]
    s, obs = paper_run["session"], paper_run["obs"]
    assert s.k == ref["k"] and s.settle_time == ref["settle_time"] and obs.t == ref["t"]
    np.testing.assert_array_equal(obs.x, np.asarray(ref["x"]))
    np.testing.assert_array_equal(obs.theta, np.asarray(ref["theta"]))


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
