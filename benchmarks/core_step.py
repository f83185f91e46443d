"""Per-step cost of the core lock-step loop (the paper scenario as the ROS graph steps it).

``run_sampled(PAPER)`` (N = 100, 2 ms control period: observe, sense, law, advance), in one
process, interleaved, medians over ``--repeats``: ``before`` (the numpy path,
``CONTGRASP_KERNELS=0``, and the general closest-point search) against ``after`` (the compiled
kernels, the structured O(N^2) solve and the circle's closed-form projection); both must end in
the same state. Then the breakdown per step, the scaling with N and the floor. Results:
benchmarks/RESULTS.md.

    python benchmarks/core_step.py                 # full paper run, 3 repeats, N-scaling
    python benchmarks/core_step.py --repeats 1 --scaling-steps 100
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import replace
from typing import Any, Iterator

import numpy as np

from contgrasp_core.boundary import Boundary, fourier_polar
from contgrasp_core.control import feedback_at_joints
from contgrasp_core.rod import Obstacle, RodSystem, _kernels, integrator
from contgrasp_core.contact import sense
from contgrasp_core.rod.session import LoopSession
from contgrasp_core.scenario import PAPER, Scenario


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


@contextmanager
def mode(after: bool, old_threads: bool = False) -> Iterator[None]:
    """Kernels on (after) or off (before); ``old_threads`` also lifts the one-BLAS-thread scope."""
    saved = (_kernels.ENABLED, integrator.single_thread_blas)
    _kernels.ENABLED = after
    if old_threads:
        import contextlib

        integrator.single_thread_blas = contextlib.nullcontext  # type: ignore[assignment]
    try:
        yield
    finally:
        _kernels.ENABLED, integrator.single_thread_blas = saved


class Timed:
    """Wraps a callable and accumulates its wall time."""

    def __init__(self, fn: Any) -> None:
        self.fn, self.total, self.calls = fn, 0.0, 0

    def __call__(self, *a: Any, **k: Any) -> Any:
        t = time.perf_counter()
        try:
            return self.fn(*a, **k)
        finally:
            self.total += time.perf_counter() - t
            self.calls += 1


def run(scenario: Scenario, after: bool, steps: int | None = None, *, breakdown: bool = False,
        old_threads: bool = False) -> dict[str, Any]:
    """The lock-step loop of ``run_sampled`` with per-phase timers; ``steps`` caps the control steps."""
    obj = scenario.object.boundary()
    # before: the general closest-point search for the sensing (how circles were projected)
    sensing: Boundary = obj
    if not after and obj.kind == "circle":  # the same circle as a polar curve without harmonics
        sensing = fourier_polar(obj.params["R"], center=obj.params["center"])
    system = RodSystem(scenario.rod, Obstacle(obj))
    gains = scenario.feedback_gains
    phases = dict.fromkeys(("observe", "sense", "law", "advance"), 0.0)
    saved_solve = integrator.solve
    solve_t, nsys_t = Timed(integrator.solve), Timed(system._newton_system)
    if breakdown:  # (the integrator looks the solve up as its module's ``solve``)
        integrator.solve = solve_t  # type: ignore[assignment]
        object.__setattr__(system, "_newton_system", nsys_t)
    try:
        with mode(after, old_threads):
            session = LoopSession(system, scenario.loop)
            t_all = time.perf_counter()
            while True:
                t0 = time.perf_counter()
                obs = session.observe()
                t1 = time.perf_counter()
                phases["observe"] += t1 - t0
                if session.finished or (steps is not None and session.k >= steps):
                    break
                c = sense(obs.shape, sensing, obs.radius, tol=scenario.sensing.contact_tolerance)
                t2 = time.perf_counter()
                fb = feedback_at_joints(scenario.rod, gains, c.rho, c.alpha)
                t3 = time.perf_counter()
                session.advance(fb)
                t4 = time.perf_counter()
                phases["sense"] += t2 - t1
                phases["law"] += t3 - t2
                phases["advance"] += t4 - t3
            wall = time.perf_counter() - t_all
    finally:
        integrator.solve = saved_solve
        if breakdown:
            object.__delattr__(system, "_newton_system")
    k = max(session.k, 1)
    out = {"k": session.k, "wall": wall, "per_step_ms": 1e3 * wall / k, "iterations": session.iterations,
           "settle_time": session.settle_time, "theta": session.state.theta.copy(),
           "phases_ms": {p: 1e3 * v / k for p, v in phases.items()}}
    if breakdown:
        matrix = nsys_t.total
        out["advance_split_ms"] = {"newton matrix + residual": 1e3 * matrix / k, "solve": 1e3 * solve_t.total / k,
                                   "rest of advance": 1e3 * (phases["advance"] - matrix - solve_t.total) / k}
        out["per_iteration_us"] = {"newton matrix + residual": 1e6 * matrix / max(nsys_t.calls, 1),
                                   "solve": 1e6 * solve_t.total / max(solve_t.calls, 1)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3, help="interleaved before/after runs (medians)")
    ap.add_argument("--steps", type=int, default=None, help="cap the control steps (default: the whole run)")
    ap.add_argument("--scaling", type=str, default="50,100,200,400", help="element counts for the scaling table")
    ap.add_argument("--scaling-steps", type=int, default=100, help="control steps per scaling run")
    ap.add_argument("--old-threads", action="store_true",
                    help="also time 'before' with OpenBLAS's default threads (as the old code ran)")
    args = ap.parse_args()
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} cores; "
          f"load average at start {load()}")
    run(PAPER, True, 5)  # compile / load the kernels' cache outside the timings
    run(PAPER, False, 5)
    before, after = [], []
    for r in range(args.repeats):
        before.append(run(PAPER, False, args.steps))
        after.append(run(PAPER, True, args.steps))
        print(f"  repeat {r + 1}: before {before[-1]['per_step_ms']:.3f} ms/step, after {after[-1]['per_step_ms']:.3f} "
              f"ms/step ({before[-1]['k']} steps; load {load()})", flush=True)
    b0, a0 = before[0], after[0]
    same = (b0["k"] == a0["k"] and b0["settle_time"] == a0["settle_time"] and b0["iterations"] == a0["iterations"])
    dth = float(np.abs(b0["theta"] - a0["theta"]).max())
    print(f"same run: steps {a0['k']} / {b0['k']}, settle {a0['settle_time']} / {b0['settle_time']}, Newton "
          f"iterations {a0['iterations']} / {b0['iterations']}, final angles differ by {dth:.2e} rad -> "
          f"{'IDENTICAL (to 1e-9)' if same and dth < 1e-9 else 'DIFFERENT'}")
    mb = float(np.median([r["per_step_ms"] for r in before]))
    ma = float(np.median([r["per_step_ms"] for r in after]))
    pair = float(np.median([b["per_step_ms"] / a["per_step_ms"] for b, a in zip(before, after, strict=True)]))
    print(f"per control step (2 ms simulated): before {mb:.3f} ms, after {ma:.3f} ms (medians of {args.repeats}); "
          f"ratio of medians {mb / ma:.2f}x, median of the paired ratios {pair:.2f}x; fastest after "
          f"{min(r['per_step_ms'] for r in after):.3f} ms (real-time factor {2.0 / ma:.1f}x at the median)")
    if args.old_threads:
        ot = run(PAPER, False, args.steps, old_threads=True)
        print(f"before with OpenBLAS default threads: {ot['per_step_ms']:.3f} ms/step ({ot['per_step_ms'] / ma:.1f}x "
              f"the after median)")

    print("\nbreakdown per control step (ms; one instrumented run each):")
    bb, ba = run(PAPER, False, args.steps, breakdown=True), run(PAPER, True, args.steps, breakdown=True)
    print(f"  {'phase':28s} {'before':>8s} {'after':>8s}")
    for p in ("observe", "sense", "law", "advance"):
        print(f"  {p:28s} {bb['phases_ms'][p]:8.3f} {ba['phases_ms'][p]:8.3f}")
    for p in bb["advance_split_ms"]:
        print(f"    {p:26s} {bb['advance_split_ms'][p]:8.3f} {ba['advance_split_ms'][p]:8.3f}")
    print(f"  per Newton iteration (us): matrix + residual {bb['per_iteration_us']['newton matrix + residual']:.0f} -> "
          f"{ba['per_iteration_us']['newton matrix + residual']:.0f}, solve (LAPACK -> structured) "
          f"{bb['per_iteration_us']['solve']:.0f} -> {ba['per_iteration_us']['solve']:.0f}; "
          f"{ba['iterations'] / max(ba['k'], 1):.2f} iterations per step")

    print(f"\nscaling (first {args.scaling_steps} control steps, time per step in ms, median of {args.repeats}; ratio = "
          "median of the paired ratios; solve / matrix = ms per step in the structured solve / in the Newton matrix + "
          "residual incl. the feedback's sensing, after):")
    print(f"  {'N':>5s} {'before':>9s} {'after':>9s} {'ratio':>6s} {'solve':>7s} {'matrix':>7s}  iterations/step")
    for n in (int(v) for v in args.scaling.split(",")):
        sc = replace(PAPER, rod=replace(PAPER.rod, n_elements=n))
        bs, as_ = [], []
        for _ in range(args.repeats):  # interleaved pairs
            bs.append(run(sc, False, args.scaling_steps)["per_step_ms"])
            as_.append(run(sc, True, args.scaling_steps)["per_step_ms"])
        br = run(sc, True, args.scaling_steps, breakdown=True)
        mb_, ma_ = float(np.median(bs)), float(np.median(as_))
        pr = float(np.median([b / a for b, a in zip(bs, as_, strict=True)]))
        print(f"  {n:5d} {mb_:9.3f} {ma_:9.3f} {pr:6.2f} {br['advance_split_ms']['solve']:7.3f} "
              f"{br['advance_split_ms']['newton matrix + residual']:7.3f}  {br['iterations'] / max(br['k'], 1):.2f}",
              flush=True)
    print(f"load average at end {load()}")


if __name__ == "__main__":
    main()
