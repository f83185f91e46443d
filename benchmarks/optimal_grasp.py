"""Benchmark: the fast optimal-grasp solver against the paper's forward-backward sweep.

For the three Fig. 2 objects at N = 500 nodes (chi = 10), in one process: the fast solver at tol
1e-11 gives J*; (a) the sweep at the paper's eta = 1e-6 until J <= 1.01 J* (or a budget), (b) the
sweep at the largest stable eta, (c) the fast solver with ``cost_tol`` = 1e-7 (and (c') at its
default tol); prints the time ratios (b)/(c) and (a)/(c). All start from the same initial
curvature. Method and results: docs/optimal.md, "Measured behaviour".

Usage:  .venv/bin/python benchmarks/optimal_grasp.py [--nodes 500] [--paper-budget 3000]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small banded solves: threads only add overhead

import numpy as np  # noqa: E402

from contgrasp_core.optimal import paper_problem, solve, forward_backward


def largest_stable_eta(problem, probe_iterations: int = 300, lo: float = 1e-6, hi: float = 1e-3) -> float:
    etas = lo * np.sqrt(2.0) ** np.arange(int(np.log(hi / lo) / np.log(np.sqrt(2.0))) + 1)
    best = lo
    for eta in etas:
        r = forward_backward(problem, eta=float(eta), max_iterations=probe_iterations)
        hist = r.history["cost"]
        ok = r.iterations == probe_iterations and np.all(np.isfinite(hist)) and hist[-1] < hist[0]
        if not ok:
            break
        best = float(eta)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=500)
    ap.add_argument("--paper-budget", type=int, default=3000, help="iterations for the sweep at eta = 1e-6")
    ap.add_argument("--max-sweep", type=int, default=60000, help="iteration cap for the best-eta sweep")
    ap.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    ap.add_argument("--fast-only", action="store_true",
                    help="only time the fast solver (cost_tol 1e-7, median of 15) per object, no sweeps: for "
                         "comparing two checkouts side by side (PYTHONPATH=<checkout> ...)")
    args = ap.parse_args()
    rows = []
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, N = {args.nodes}, "
        f"load average at start {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    for name in ("circle", "ellipse", "deformed"):
        p = paper_problem(name, nodes=args.nodes)
        if args.fast_only:
            solve(p, cost_tol=1e-7)
            t_fast = statistics.median([solve(p, cost_tol=1e-7).wall_time for _ in range(15)])
            print(f"[{name}] fast solver {1e3 * t_fast:.2f} ms (median of 15), J = {solve(p, cost_tol=1e-7).cost:.10g}")
            continue
        ref = solve(p, tol=1e-11)
        j_star = ref.cost
        target = 1.01 * j_star
        # (c) fast solver, default settings
        times, fast = [], None
        for _ in range(6):
            fast = solve(p, cost_tol=1e-7)
            times.append(fast.wall_time)
        fast_err = abs(fast.cost - j_star) / j_star
        t_default = statistics.median([solve(p).wall_time for _ in range(6)])
        # (a) the paper's eta
        a = forward_backward(p, eta=1e-6, max_iterations=args.paper_budget, target_cost=target)
        a_err = (a.cost - j_star) / j_star
        # (b) best stable eta
        eta_b = largest_stable_eta(p)
        while True:
            b = forward_backward(p, eta=eta_b, max_iterations=args.max_sweep, target_cost=target)
            if b.converged or "diverged" not in b.message and "singular" not in b.message:
                break
            eta_b /= np.sqrt(2.0)
        b_err = (b.cost - j_star) / j_star
        times += [solve(p, cost_tol=1e-7).wall_time for _ in range(6)]
        t_fast = statistics.median(times)
        row = {
            "object": name,
            "J_star": j_star,
            "fast_time_s": t_fast,
            "fast_iterations": fast.iterations,
            "fast_sqp_steps": int(fast.history["sqp_steps"]),
            "fast_coarse_sqp_steps": int(fast.history["coarse_sqp_steps"]),
            "fast_coarse_iterations": int(fast.history["coarse_iterations"]),
            "fast_time_min_s": min(times),
            "fast_rel_cost_error": fast_err,
            "fast_residual": fast.residual,
            "fast_default_tol_time_s": t_default,
            "paper_eta_reached_1pct": bool(a.converged),
            "paper_eta_iterations": a.iterations,
            "paper_eta_time_s": a.wall_time,
            "paper_eta_rel_cost_error": a_err,
            "paper_eta_inadmissible_iterations": a.constraints.inadmissible_iterations,
            "best_eta": eta_b,
            "best_eta_reached_1pct": bool(b.converged),
            "best_eta_iterations": b.iterations,
            "best_eta_time_s": b.wall_time,
            "best_eta_rel_cost_error": b_err,
            "best_eta_inadmissible_iterations": b.constraints.inadmissible_iterations,
            "ratio_best_eta_over_fast": b.wall_time / t_fast,
            "ratio_paper_eta_over_fast": a.wall_time / t_fast,
        }
        rows.append(row)
        print(
            f"\n[{name}] J* = {j_star:.10g}\n"
            f"  (c) fast      : {t_fast * 1e3:8.2f} ms (min {min(times) * 1e3:.2f})  ({fast.iterations} fine "
            f"Newton steps, {row['fast_sqp_steps']} of them SQP; "
            f"coarse: {row['fast_coarse_sqp_steps']} SQP + "
            f"{row['fast_coarse_iterations']} damped), rel. cost error {fast_err:.1e}, "
            f"residual {fast.residual:.1e}\n"
            f"  (c') fast, default tol 1e-9: {t_default * 1e3:8.2f} ms\n"
            f"  (a) sweep 1e-6: {a.wall_time:8.2f} s   {a.iterations} its, "
            f"{'reached 1%' if a.converged else 'NOT within 1%'}: rel. cost error {a_err:.3g}, "
            f"{a.constraints.inadmissible_iterations} inadmissible iterates\n"
            f"  (b) sweep {eta_b:.3g}: {b.wall_time:8.2f} s   {b.iterations} its, "
            f"{'reached 1%' if b.converged else 'NOT within 1%'}: rel. cost error {b_err:.3g}, "
            f"{b.constraints.inadmissible_iterations} inadmissible iterates\n"
            f"  ratio (b)/(c) = {row['ratio_best_eta_over_fast']:.0f}x ; "
            f"(a)/(c) = {row['ratio_paper_eta_over_fast']:.0f}x"
            f"{'' if a.converged else ' (lower bound: (a) never reached 1%)'}"
        )
    print(f"load average at end {os.getloadavg()[0]:.2f}")
    if rows:
        print("\nsummary: ratio (b)/(c) = " + ", ".join(f"{r['object']} {r['ratio_best_eta_over_fast']:.0f}x" for r in rows))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
