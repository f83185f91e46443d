"""Benchmark: the core lock-step loop's phases, this checkout against another one (A/B).

The paper scenario run to the end as ``run_sampled`` steps it (observe, sense with the object's
``Boundary``, the law ``feedback_at_joints``, ``LoopSession.advance``), timed per phase, plus the
feedback's first-order hold inside the Newton iterations (``HeldExpansion.couple_and_jacobian``,
part of ``advance``). Each run is a fresh subprocess with ``PYTHONPATH`` set to one checkout;
the two checkouts alternate (old-new, new-old, ...) so that both sample the machine's load over
the same period. Medians per phase and the median of the paired ratios; the runs of each
checkout must end in the same state bit for bit, and the step counts, Newton iterations and the
largest final-angle difference between the checkouts are printed. Only public APIs are used, so the other checkout can
be any earlier commit, e.g. ``git archive COMMIT | tar -x -C /tmp/base`` (its numba cache is
compiled by the first run, outside the timings: each run first steps 5 times untimed).

    python benchmarks/core_ab.py --against /tmp/base [--pairs 8]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

PHASES = ("observe", "sense", "law", "advance", "held feedback (in advance)", "total")


def child() -> None:
    """One full paper run with phase timers; prints a JSON object."""
    from contgrasp_core.contact import sense
    from contgrasp_core.control import feedback_at_joints, rod_feedback
    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.session import LoopSession
    from contgrasp_core.scenario import PAPER

    held = [0.0]
    inner = rod_feedback.HeldExpansion.couple_and_jacobian

    def timed(self: Any, *a: Any, **k: Any) -> Any:
        t = time.perf_counter()
        try:
            return inner(self, *a, **k)
        finally:
            held[0] += time.perf_counter() - t

    rod_feedback.HeldExpansion.couple_and_jacobian = timed  # type: ignore[method-assign]

    def run(steps: int | None) -> dict[str, Any]:
        boundary = PAPER.object.boundary()
        session = LoopSession(RodSystem(PAPER.rod, Obstacle(boundary)), PAPER.loop)
        gains, tol = PAPER.feedback_gains, PAPER.sensing.contact_tolerance
        ph = dict.fromkeys(PHASES[:4], 0.0)
        held[0] = 0.0
        t_all = time.perf_counter()
        while True:
            t0 = time.perf_counter()
            obs = session.observe()
            t1 = time.perf_counter()
            ph["observe"] += t1 - t0
            if session.finished or (steps is not None and session.k >= steps):
                break
            c = sense(obs.shape, boundary, obs.radius, tol=tol)
            t2 = time.perf_counter()
            fb = feedback_at_joints(PAPER.rod, gains, c.rho, c.alpha)
            t3 = time.perf_counter()
            session.advance(fb)
            t4 = time.perf_counter()
            ph["sense"] += t2 - t1
            ph["law"] += t3 - t2
            ph["advance"] += t4 - t3
        wall = time.perf_counter() - t_all
        k = max(session.k, 1)
        out: dict[str, Any] = {p: 1e3 * v / k for p, v in ph.items()}
        out.update({"held feedback (in advance)": 1e3 * held[0] / k, "total": 1e3 * wall / k, "k": session.k,
                    "iterations": session.iterations, "theta": session.state.theta.tolist()})
        return out

    run(5)  # (kernels loaded or compiled outside the timing)
    print(json.dumps(run(None)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", type=Path, help="the other checkout (old); this one is new")
    ap.add_argument("--pairs", type=int, default=8, help="old/new run pairs (alternating order)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child()
        return
    if args.against is None:
        ap.error("--against DIR is required")
    roots = {"old": str(args.against.resolve()), "new": str(Path(__file__).resolve().parents[1])}
    res: dict[str, list[dict[str, Any]]] = {"old": [], "new": []}
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} cores, paper scenario; old = {roots['old']}, "
          f"new = {roots['new']}; load average at start {os.getloadavg()[0]:.2f}")
    for i in range(args.pairs):
        for v in ("old", "new") if i % 2 == 0 else ("new", "old"):
            env = dict(os.environ, PYTHONPATH=roots[v])
            out = subprocess.run([sys.executable, __file__, "--child"], env=env, capture_output=True, text=True, check=True)
            res[v].append(json.loads(out.stdout))
        print(f"  pair {i + 1}: old {res['old'][-1]['total']:.3f}, new {res['new'][-1]['total']:.3f} ms/step "
              f"(load {os.getloadavg()[0]:.2f})", flush=True)
    old, new = res["old"][0], res["new"][0]
    same = all((r["theta"], r["k"], r["iterations"]) == (v[0]["theta"], v[0]["k"], v[0]["iterations"])
               for v in res.values() for r in v)
    diff = max(abs(a - b) for a, b in zip(old["theta"], new["theta"], strict=True))
    print(f"control steps old {old['k']} / new {new['k']}, Newton iterations {old['iterations']} / "
          f"{new['iterations']}; final angles differ by {diff:.3g} rad; each checkout's runs equal bit for bit: {same}")
    print(f"  {'ms per control step (medians)':30s} {'old':>7s} {'new':>7s} {'old/new (paired)':>17s}")
    for key in PHASES:
        old = statistics.median(r[key] for r in res["old"])
        new = statistics.median(r[key] for r in res["new"])
        ratio = statistics.median(a[key] / b[key] for a, b in zip(res["old"], res["new"], strict=True))
        print(f"  {key:30s} {old:7.3f} {new:7.3f} {ratio:17.2f}")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
