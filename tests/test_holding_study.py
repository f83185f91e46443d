"""The holding study (contgrasp_core.holding_study): rank correlations against known
relations, a tiny real study that resumes without recomputing, and its figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contgrasp_core.holding import HoldSettings
from contgrasp_core.holding_study import PREDICTORS, RESPONSES, StudySpec, correlations, load_results, run_study


def _rows(n: int, relation) -> list[dict]:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(1)
    rows = []
    for i in range(n):
        q = float(rng.uniform(0.1, 2.0))
        row = {"key": f"grid:{i},0", "status": "ok", **{p: q for p in PREDICTORS}}
        row.update({r: relation(q, rng) for r in RESPONSES})
        rows.append(row)
    rows.append({"key": "grid:99,0", "status": "RunFailure: did not settle", "static_Q1": 5.0})
    return rows


def test_correlations_find_monotone_relations_and_none_in_noise() -> None:
    up = correlations(_rows(20, lambda q, rng: q**3 + 1.0), boot=300)
    assert up["static_Q1"]["capacity_min"]["rho"] == 1.0 and up["Q3"]["stiffness_min"]["low"] > 1.0 - 1e-12
    assert up["Q1"]["stiffness_det"]["n"] == 20  # (the failed pose is left out)
    down = correlations(_rows(20, lambda q, rng: -np.log(q)), boot=300)
    assert down["Q2"]["capacity_min"]["rho"] < -1.0 + 1e-12
    noise = correlations(_rows(40, lambda q, rng: float(rng.normal())), boot=500)
    c = noise["static_Q1"]["capacity_min"]
    assert c["low"] < 0 < c["high"] and abs(c["rho"]) < 0.5


def test_a_tiny_study_runs_resumes_and_draws(tmp_path: Path) -> None:
    """Two base poses of the circle's map and the three optima, a coarse rod and short ramps:
    every pose gets a result line; running again computes nothing and returns the same rows."""
    spec = StudySpec(object="circle", psi_steps=2, d_steps=1, nodes=31,
                     hold=HoldSettings(directions=1, ramp_time=0.4, hold_time=0.3, release_time=0.3))
    out = tmp_path / "study.jsonl"
    qm, rows = run_study(spec, out, executor="serial")
    assert sorted(r["key"] for r in rows) == ["grid:0,0", "grid:1,0", "optimum:Q1", "optimum:Q2", "optimum:Q3"]
    ok = [r for r in rows if r["status"] == "ok"]
    assert ok, [r["status"] for r in rows]
    for r in ok:
        assert np.asarray(r["stiffness"]).shape == (3, 3) and len(r["capacity"]) == 3 and r["Q1"] > 0
    lines = out.read_text().splitlines()
    qm2, rows2 = run_study(spec, out, executor="serial")
    assert out.read_text().splitlines() == lines and rows2 == rows
    assert load_results(out)[0]["key"] == "spec"
    from contgrasp_core.figures.holding import study_figure

    fig = study_figure(qm, rows)
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    assert any("static Q1" in t for t in titles) and any("capacity" in t for t in titles)
