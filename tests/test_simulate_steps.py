"""``contgrasp simulate --json`` reports how many steps the run took and its wall time."""

from __future__ import annotations

import json

import pytest

from contgrasp_core.cli import main


@pytest.mark.parametrize("extra,periods", [(["--dt", "0.01"], 10), (["--control-period", "0.005"], 20),
                                           # the sampled loop held to first order, as the ROS graph steps it (issue 31: 0 steps)
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
