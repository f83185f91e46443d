"""Benchmark: what a pose of the holding study costs, on each executor and without the kernels.

Two poses of `contgrasp holding-study --object circle --law reactive --support 0 --arm rod
--contact-wait 3 --rate 0.25 --ramp-time 8` (grid distances 5 and 9 paper units; the close,
the free release, the stiffness probes and six capacity ramps: `holding.study.study_pose`),
run in one process serially, on the process pool with two workers and on a local Dask cluster
of two worker processes; then one pose serially with the rod's compiled kernels switched off
(`contgrasp_core.rod._kernels.ENABLED = False`: numpy and LAPACK). Wall seconds and ratios to
the serial run with the kernels; every run must give the same outcome per pose.

Usage: .venv/bin/python benchmarks/holding_study.py
"""

from __future__ import annotations

import os
import time
from typing import Any

import distributed

from contgrasp_core.holding import HoldSettings
from contgrasp_core.holding.study import StudySpec, _task
from contgrasp_core.quality_map import disc_pose
from contgrasp_core.rod import _kernels
from contgrasp_core.executors import run_tasks


def _poses(spec: StudySpec) -> list[Any]:
    b = spec.map_spec().boundary()
    out = []
    for d in (5.0, 9.0):
        p = disc_pose(b, 0.0, d)
        out.append((spec, f"d={d:g}", (p.x, p.y, p.theta), (float("nan"),) * 3))
    return out


def _run(items: list[Any], executor: str, scheduler: str | None = None) -> tuple[float, list[dict[str, Any]]]:
    t0 = time.perf_counter()
    rows = list(run_tasks(_task, items, executor, workers=2, scheduler=scheduler))
    return time.perf_counter() - t0, rows


def main() -> None:
    hold = HoldSettings(directions=4, support=0.0, contact_wait=3.0, rate=0.25, ramp_time=8.0)
    spec = StudySpec(object="circle", law="reactive", arm="rod", hold=hold)
    items = _poses(spec)
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    _run(items[:1], "serial")  # (kernels compiled and loaded, caches warm)
    results: dict[str, tuple[float, int, list[dict[str, Any]]]] = {}
    wall, rows = _run(items, "serial")
    results["serial, kernels"] = (wall, len(items), rows)
    wall, rows = _run(items, "processes")
    results["processes x2, kernels"] = (wall, len(items), rows)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        wall, rows = _run(items, "dask", cluster.scheduler_address)
    results["dask x2, kernels"] = (wall, len(items), rows)
    _kernels.ENABLED = False
    try:
        wall, rows = _run(items[:1], "serial")
    finally:
        _kernels.ENABLED = True
    results["serial, no kernels"] = (wall, 1, rows)
    ref = results["serial, kernels"][0] / results["serial, kernels"][1]
    outcomes = {r["key"]: (r["outcome"], r.get("capacity_min")) for r in results["serial, kernels"][2]}
    print(f"{'':24s} {'poses':>5s} {'wall s':>8s} {'s/pose':>8s} {'x serial':>9s}  outcome (capacity_min N) per pose")
    for name, (wall, n, rows) in results.items():
        got = {r["key"]: (r["outcome"], r.get("capacity_min")) for r in rows}
        same = all(outcomes[k] == v for k, v in got.items())
        text = ", ".join(f"{k}: {o} ({c:.3f})" if c is not None else f"{k}: {o}" for k, (o, c) in got.items())
        print(f"{name:24s} {n:5d} {wall:8.1f} {wall / n:8.1f} {wall / n / ref:9.2f}  {text}"
              f"{'' if same else '  DIFFERS from serial'}")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
