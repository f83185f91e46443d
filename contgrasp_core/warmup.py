"""Compile the rod engine's and the sensing's kernels once: ``python -m contgrasp_core.warmup``.

``contgrasp.sh setup`` runs it, so the first real run does not pay numba's compilation (~10-17 s
on 2 cores; with a current on-disk cache this only loads it, well under a second). It runs a tiny
closed-loop simulation through every path that uses a kernel, so it sits above the loop's
modules; the kernels themselves (:mod:`contgrasp_core.rod._kernels`) import none of them.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from contgrasp_core.boundary import ellipse
from contgrasp_core.control import paper_gains
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop
from contgrasp_core.rod.integrator import RodSystem
from contgrasp_core.rod.obstacle import Obstacle
from contgrasp_core.rod.session import run_sampled
from contgrasp_core.scenario import PAPER

__all__ = ["warm"]


def warm() -> float:
    """Compile (or load from numba's on-disk cache) every kernel by running a tiny closed-loop
    simulation through the code paths that use them (the lock-step loop with the held expansion
    and the continuous loop, both around a circle, with contact); returns the seconds it took."""
    t0 = time.perf_counter()
    ellipse(2.0, 1.0).project(np.array([[0.5, 0.25]]))  # contgrasp_core._geometry
    rod = replace(PAPER.rod, n_elements=12)
    run_sampled(replace(PAPER, rod=rod, loop=replace(PAPER.loop, duration=0.01)))
    system = RodSystem(rod, Obstacle(PAPER.object.boundary()))
    run_closed_loop(system, paper_gains(rod, 0.025), ClosedLoopConfig(duration=0.02, dt=0.01))
    return time.perf_counter() - t0


if __name__ == "__main__":
    warm()
