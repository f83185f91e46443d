"""Benchmark: the implicit step with bounded muscles, backtracking against the plain Newton step.

The reactive holding law's grasp of the paper's fixed circle with 50 kPa muscles
(`contgrasp simulate --law reactive --max-muscle-stress 50000`: the continuous loop, steps of at
most 10 ms), 2.5 s of it, run in one process twice: with the engine's backtracking at the
saturation's kink (docs/rod.md, "Newton across the kink") and with the plain Newton step
(`contgrasp_core.rod.integrator.LAM_MIN = 1.0`: every step taken whole). CPU seconds, the
integrator's steps and Newton iterations, the arm's end state, and the ratio of the CPU times.

Usage: .venv/bin/python benchmarks/bounded_muscles.py
"""

from __future__ import annotations

import os
import time
from dataclasses import replace

import numpy as np

from contgrasp_core.rod import integrator
from contgrasp_core.rod.closed_loop import ClosedLoopResult, run_closed_loop
from contgrasp_core.scenario import PAPER

DURATION = 2.5  # s: the plain step's cost grows from t = 2 s on (about 400 s of CPU for the 4 s run)


def _run(lam_min: float) -> tuple[float, ClosedLoopResult]:
    s = replace(PAPER, law="reactive", rod=replace(PAPER.rod, max_muscle_stress=50000.0),
                loop=replace(PAPER.loop, duration=DURATION, control_period=None, dt=0.01))
    integrator.LAM_MIN = lam_min
    t0 = time.process_time()
    res = run_closed_loop(s.system(), s.feedback_gains, s.loop, law=s.controller())
    return time.process_time() - t0, res


def main() -> None:
    print(f"load average at start {os.getloadavg()[0]:.2f}")
    default = integrator.LAM_MIN
    _run(default)  # (kernels compiled and loaded)
    rows = {"backtracking": _run(default), "plain Newton step": _run(1.0)}
    integrator.LAM_MIN = default
    print(f"{'step':<20} {'CPU s':>8} {'steps':>8} {'Newton its':>11} {'tip x, y (m)':>22}")
    for name, (cpu, res) in rows.items():
        tip = (float(res.x[-1][-1, 0]), float(res.x[-1][-1, 1]))
        print(f"{name:<20} {cpu:8.2f} {res.integrator_steps:8d} {res.newton_iterations:11d} "
              f"{tip[0]:10.5f} {tip[1]:10.5f}")
    a, b = rows["backtracking"][0], rows["plain Newton step"][0]
    print(f"plain / backtracking CPU: {b / a:.1f}")
    tips = [np.asarray(r.x[-1][-1]) for _, r in rows.values()]
    print(f"tip positions differ by {1e3 * float(np.linalg.norm(tips[0] - tips[1])):.3f} mm")


if __name__ == "__main__":
    main()
