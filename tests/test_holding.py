"""Holding (contgrasp_core.holding, ``contgrasp hold``): the measured grasp stiffness predicts
the response to another small load, the capacity ramps end in a stated escape, and the command
reports stiffness, capacity and quality."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.holding import HoldExperiment, HoldSettings, wrench_directions
from contgrasp_core.scenario import PAPER

pytestmark = pytest.mark.heavy(per_module=True)  # (its tests share one grasp released and measured: one shard measures it)

SCENARIO = PAPER  # (a coarser rod's tip strikes the object deeper than the model holds: docs/rod.md, "Validity")


@pytest.fixture(scope="module")
def experiment() -> HoldExperiment:
    exp = HoldExperiment(SCENARIO, HoldSettings())
    exp.grasp()
    exp.release()
    return exp


@pytest.fixture(scope="module")
def stiffness(experiment: HoldExperiment) -> tuple[np.ndarray, np.ndarray]:
    """The experiment's (K, C): six probe runs, deterministic, so measured once for the module."""
    return experiment.stiffness()


def test_the_measured_stiffness_predicts_a_combined_small_load(experiment: HoldExperiment,
                                                               stiffness: tuple[np.ndarray, np.ndarray]) -> None:
    """K comes from single-axis probes; a combined small wrench (never applied to measure it)
    moves the object by C w, to 5 % (measured 0.8 %: the grasp is linear at this load). As in
    the probes, the response is the half difference of +w and -w: it cancels the released
    grasp's slow drift (the closed loop's own, ~1e-3 rad/s without load, checked here)."""
    _, compliance = stiffness
    w = np.array([1.2e-3, -0.8e-3, 3e-5])
    moved = 0.5 * (experiment.displacement_under(w) - experiment.displacement_under(-w))
    predicted = compliance @ w
    assert np.linalg.norm(moved - predicted) < 0.05 * np.linalg.norm(predicted), (moved, predicted)
    drift = experiment.displacement_under(np.zeros(3))
    assert np.linalg.norm(drift) < 0.5 * np.linalg.norm(predicted)  # (the load, not the drift, is measured)


def test_the_grasp_adds_to_the_support_and_gives_way_under_a_large_load(experiment: HoldExperiment,
                                                                       stiffness: tuple[np.ndarray, np.ndarray]) -> None:
    """The grasp's own stiffness is positive along x and y (it adds to the support); a ramp
    along +x ends with the object escaped, as a result (no exception), beyond what the support
    alone carries at the escape distance."""
    k, _ = stiffness
    assert k[0, 0] > 0 and k[1, 1] > 0
    cap = experiment.capacity(np.array([1.0, 0.0, 0.0]))
    assert not cap.held and cap.reason in ("moved", "turned", "contact lost") or cap.reason.startswith("simulation failed")
    support_alone = experiment.settings.support * experiment.escape.escape_distance
    assert cap.magnitude > support_alone


def test_wrench_directions_are_unit_and_cover_forces_and_torques() -> None:
    d = wrench_directions(6)
    assert d.shape == (8, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(d[:6].sum(axis=0), 0.0, atol=1e-12)
    assert d[6, 2] == 1.0 and d[7, 2] == -1.0


def test_bad_hold_settings_are_clear_errors() -> None:
    for bad in (dict(mu=-0.1), dict(probe=(1e-3, 1e-3)), dict(rate=float("nan")), dict(directions=0)):
        with pytest.raises(InvalidParameterError, match="hold"):
            HoldSettings(**bad)  # type: ignore[arg-type]
    from contgrasp_core.rod.body import ObjectDynamics
    with pytest.raises(InvalidParameterError, match="fixed"):
        HoldExperiment(replace(PAPER, dynamics=ObjectDynamics("free")))


def test_hold_command_reports_stiffness_capacity_and_quality() -> None:
    cmd = [sys.executable, "-m", "contgrasp_core.cli", "hold", "--directions", "2", "--ramp-time", "1.5"]
    out = json.loads(subprocess.run(cmd + ["--json"], capture_output=True, text=True, check=True).stdout)
    assert np.asarray(out["stiffness"]).shape == (3, 3) and len(out["stiffness_eigenvalues"]) == 3
    assert len(out["capacity"]) == 4
    assert out["capacity_min"] == min(c["magnitude"] for c in out["capacity"])
    # (a direction that held to the ramp's end gives a lower bound, said so; never a bare ramp end)
    weakest = min(out["capacity"], key=lambda c: c["magnitude"])
    assert out["capacity_is_bound"] is weakest["held"] and out["capacity_min_reason"] == weakest["reason"]
    assert all(("a lower bound" in c["reason"]) == c["held"] for c in out["capacity"])
    assert out["Q1"] > 0 and out["Q2"] > 0 and 0 < out["Q3"] <= 1
    # (a held run reports its grasp's validity and effort too: tests/test_validity.py, bounded muscles)
    assert out["held"] is True and out["validity"]["valid"] is True and out["peak_couple"] > 0 and out["peak_couple_ratio"] is None
    # (unbounded muscles: the wrapped rest shape with friction resists every direction, no ceiling)
    assert out["muscles_hold_shape"] is True and out["muscle_ceiling_min"] is None
    assert all(c["muscle_ceiling"] is None for c in out["capacity"])
    bad = subprocess.run(cmd + ["--mu", "nan"], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
