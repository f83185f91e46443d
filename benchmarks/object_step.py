"""Benchmark: what a movable object and stick-slip friction cost per control step.

The paper's sampled loop (`run_sampled`, N = 100 elements, 2 ms control period) for its first
0.6 s of simulated time (the arm swings in and touches the object at ~0.16 s), run in one
process with the object fixed (the compiled kernels' contact), fixed with stick-slip friction,
on a spring with stick-slip friction, and free: the latter three take the contact through
`contgrasp_core.rod.coupling` (numpy). Medians of `--repeat` runs, ratios to the fixed object.

Usage: .venv/bin/python benchmarks/object_step.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace

from contgrasp_core.rod.body import ObjectDynamics
from contgrasp_core.rod.session import run_sampled
from contgrasp_core.scenario import PAPER


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    base = replace(PAPER, loop=replace(PAPER.loop, duration=0.6))
    stick = replace(base.rod, friction=0.5, friction_model="stick")
    cases = {
        "fixed (paper)": base,
        "fixed, stick-slip": replace(base, rod=stick),
        "spring, stick-slip": replace(base, rod=stick, dynamics=ObjectDynamics("spring", stiffness=(2.0, 2.0, 1.25e-3),
                                                                                damping=(0.4, 0.4, 2.5e-4))),
        "free, regularised": replace(base, dynamics=ObjectDynamics("free")),
    }
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    run_sampled(replace(base, loop=replace(base.loop, duration=0.01)))  # (kernels loaded)
    times: dict[str, list[float]] = {name: [] for name in cases}
    steps = {}
    for _ in range(args.repeat):
        for name, scenario in cases.items():
            t0 = time.perf_counter()
            s = run_sampled(scenario)
            times[name].append((time.perf_counter() - t0) / s.k * 1e3)
            steps[name] = s.k
    ref = statistics.median(times["fixed (paper)"])
    print(f"{'':22s} {'ms/step':>8s} {'x fixed':>8s}  steps")
    for name in cases:
        ms = statistics.median(times[name])
        print(f"{name:22s} {ms:8.2f} {ms / ref:8.2f}  {steps[name]}")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
