"""Benchmark: quality maps with the paper's method vs the project's fast paths.

For each paper object on the same (psi, d) grid (default 24 x 6), in one process: (a) the paper's
method (each pose's inner problem by the forward-backward sweep, eq. (13); ESTIMATED from a
sample of poses, '>=' where a budget expired), (b) the serial fast path, (c) the local-process
executor. Prints wall times, per-pose medians and their ratios; then times a full 72 x 11 map
with (c) for one object.

Usage: .venv/bin/python benchmarks/quality_map.py [--psi-steps 24 --d-steps 6 --sample 3 --budget 20]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from contgrasp_core.quality_map import MapSpec, _problem, disc_pose, quality_map  # noqa: E402


def paper_pose_seconds(spec: MapSpec, psi: float, d: float, budget: float) -> tuple[float, bool]:
    from contgrasp_core.optimal import solve, forward_backward

    boundary = spec.boundary()
    problem = _problem(spec, boundary, disc_pose(boundary, psi, d))
    best = solve(problem, tol=1e-10)
    t0 = time.perf_counter()
    res = forward_backward(problem, eta=1e-6, gradient="paper", max_iterations=10**9, target_cost=1.01 * best.cost, time_budget=budget)
    secs = time.perf_counter() - t0
    return secs, bool(res.cost <= 1.01 * best.cost)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--psi-steps", type=int, default=24)
    ap.add_argument("--d-steps", type=int, default=6)
    ap.add_argument("--sample", type=int, default=3, help="poses per object timed with the paper's method")
    ap.add_argument("--budget", type=float, default=20.0, help="seconds per sampled paper-method pose")
    ap.add_argument("--full-object", default="ellipse", help="object for the full 72 x 11 map ('' to skip)")
    args = ap.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, cores {os.cpu_count()}, "
          f"grid {args.psi_steps} x {args.d_steps}, paper sample {args.sample} poses x <= {args.budget:g} s")
    print("| object | (a) paper method, est. full map | per-pose median (a) | (b) serial fast | per-pose median (b) | (c) processes | (a)/(b) | (a)/(c) | (b)/(c) | valid |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    per_pose_paper = {}
    for obj in ("circle", "ellipse", "deformed"):
        spec = MapSpec(obj, psi_steps=args.psi_steps, d_steps=args.d_steps)
        serial = quality_map(spec, executor="serial", optimise=False)
        procs = quality_map(spec, executor="processes", optimise=False)
        assert np.array_equal(serial.Q, procs.Q, equal_nan=True), "executors disagree"
        rng = np.random.default_rng(0)
        cand = np.argwhere(serial.valid)
        picks = cand[rng.choice(len(cand), size=min(args.sample, len(cand)), replace=False)]
        samples = [paper_pose_seconds(spec, float(serial.psi[i]), float(serial.d[j]), args.budget) for i, j in picks]
        med = float(np.median([s for s, _ in samples]))
        lower = not all(ok for _, ok in samples)
        per_pose_paper[obj] = (med, lower)
        n = serial.n_solves
        est = med * n
        mark = ">=" if lower else ""
        fast_med = float(np.median(serial.seconds[serial.valid]))
        print(f"| {obj} | {mark}{est:.0f} s | {mark}{med:.2f} s | {serial.wall_time:.2f} s | {fast_med * 1e3:.0f} ms | "
              f"{procs.wall_time:.2f} s | {mark}{est / serial.wall_time:.0f} | {mark}{est / procs.wall_time:.0f} | "
              f"{serial.wall_time / procs.wall_time:.2f} | {int(serial.valid.sum())}/{n} |", flush=True)
    if args.full_object:
        spec = MapSpec(args.full_object, psi_steps=72, d_steps=11)
        full = quality_map(spec, executor="processes", optimise=True)
        med, lower = per_pose_paper[args.full_object]
        mark = ">=" if lower else ""
        print(f"\nfull 72 x 11 map of the {args.full_object} (processes, with Nelder-Mead maxima): {full.wall_time:.1f} s; "
              f"paper's method for 10 poses: {mark}{10 * med:.1f} s -> ratio {mark}{10 * med / full.wall_time:.2f} "
              f"({'target met' if 10 * med > full.wall_time else 'target NOT met'})")


if __name__ == "__main__":
    main()
