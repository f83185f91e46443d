"""The arm's self-contact on a coiling case: contgrasp's implicit engine vs PyElastica's ``RodSelfContact``.

The paper's arm, no object and no drag, curled by a held couple ``u = -EI(s) kappa`` (default 45
/m) until it coils inside itself; both engines with the same damping and equivalent contact
stiffness. Reports both engines' wall seconds per simulated second (contgrasp with and without
self-contact), the smallest surface gap of each final shape and the distance between the final
centrelines; then what the self-contact search costs on the paper's runs, where the arm never
meets itself. Needs the extra ``bench`` (pyelastica). docs/rod.md, "Self-contact".

    python benchmarks/self_contact.py --duration 3 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import replace

import numpy as np

from contgrasp_core.rod import RodLoads, RodSystem, StepOptions, chain
from contgrasp_core.rod.closed_loop import run_closed_loop
from contgrasp_core.rod.session import run_sampled
from contgrasp_core.rod.self_contact import self_gap
from contgrasp_core.scenario import PAPER

from rod_vs_pyelastica import _diff, _probe, pyelastica_run


def _theta(x: np.ndarray) -> np.ndarray:
    """Element angles of a centreline (N+1, 2)."""
    e = np.diff(x, axis=0)
    return np.unwrap(np.arctan2(e[:, 1], e[:, 0]))


def contgrasp_run(model, couple: np.ndarray, duration: float, dt: float, self_contact: bool):
    """The held couple for ``duration``: final nodes, wall s, Newton iterations."""
    system = RodSystem(model, options=StepOptions(self_contact=self_contact))
    st, dt_next, iterations = system.straight_state(), dt, 0
    t0 = time.perf_counter()
    for _ in range(int(round(duration / dt))):
        st, info = system.advance(st, dt, RodLoads(couple=couple), dt_try=dt_next)
        dt_next, iterations = info["dt_next"], iterations + info["iterations"]
    return chain.nodes(model, st.theta), time.perf_counter() - t0, iterations


def paper_overhead(repeats: int) -> dict[str, float]:
    """Wall seconds of the paper's runs with self-contact over without (paired medians)."""
    def continuous(on: bool) -> float:
        system = replace(PAPER.system(), options=StepOptions(self_contact=on))
        loop = replace(PAPER.loop, control_period=None, dt=0.05, duration=3.0, settle_speed=1e-12)
        t0 = time.perf_counter()
        run_closed_loop(system, PAPER.feedback_gains, loop)
        return time.perf_counter() - t0

    def sampled(on: bool) -> float:
        system = replace(PAPER.system(), options=StepOptions(self_contact=on))
        t0 = time.perf_counter()
        run_sampled(PAPER, system)
        return time.perf_counter() - t0

    out = {}
    for run in (continuous, sampled):
        run(True), run(False)  # (warm-up)
        pairs = [(run(False), run(True)) for _ in range(repeats)]
        out[f"paper_{run.__name__}_without_s"] = float(np.median([p[0] for p in pairs]))
        out[f"paper_{run.__name__}_with_s"] = float(np.median([p[1] for p in pairs]))
        out[f"paper_{run.__name__}_cost_ratio"] = float(np.median([p[1] / p[0] for p in pairs]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kappa", type=float, default=45.0, help="held curvature, 1/m (default 45)")
    ap.add_argument("--duration", type=float, default=3.0, help="simulated seconds (default 3)")
    ap.add_argument("--dt", type=float, default=0.01, help="largest contgrasp step, s")
    ap.add_argument("--pe-dts", type=str, default="4e-5,3e-5,2e-5,1e-5", help="PyElastica steps to try, largest first")
    ap.add_argument("--repeats", type=int, default=3, help="runs per contgrasp variant (medians)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    print(f"load average at start {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores", flush=True)
    model = replace(PAPER.rod, damping=2.0, drag_normal=0.0, drag_tangential=0.0)  # (drag would slow the curl for minutes)
    couple = -model.joint_ei * args.kappa
    out: dict = {"kappa_per_m": args.kappa, "duration_s": args.duration, "damping_per_s": model.damping}
    walls: dict[bool, list[float]] = {True: [], False: []}
    final: dict[bool, np.ndarray] = {}
    for _ in range(args.repeats):
        for on in (False, True):
            x, wall, iterations = contgrasp_run(model, couple, args.duration, args.dt, on)
            walls[on].append(wall / args.duration)
            final[on] = x
            out[f"contgrasp_{'with' if on else 'without'}_self_contact_newton_iterations"] = iterations
    for on in (False, True):
        key = "with" if on else "without"
        out[f"contgrasp_{key}_self_contact_wall_per_sim_s"] = float(np.median(walls[on]))
        out[f"contgrasp_{key}_self_contact_final_self_gap_m"] = self_gap(model, _theta(final[on])).gap
    out["self_contact_cost_ratio"] = out["contgrasp_with_self_contact_wall_per_sim_s"] / out["contgrasp_without_self_contact_wall_per_sim_s"]
    k_pe = model.contact_stiffness * model.h / 3.0
    stiff = {"shear_ratio": 100.0, "stretch_ratio": 100.0, "self_contact_k": k_pe}
    dts = [float(s) for s in args.pe_dts.split(",")]
    dt = _probe(model, None, dts, 0.2, "coiling, PyElastica with RodSelfContact", held_couple=couple, filter_order=0, **stiff)
    out["pyelastica_dt"], out["pyelastica_self_contact_k"] = dt, k_pe
    if dt is not None:
        pe_x, pe_wall, ok, speed = pyelastica_run(model, None, dt, args.duration, held_couple=couple, filter_order=0, **stiff)
        dmax, s_at = _diff(model, pe_x, final[True])
        out.update({"pyelastica_stable_full_run": ok, "pyelastica_final_max_speed": speed,
                    "pyelastica_wall_per_sim_s": pe_wall / args.duration,
                    "pyelastica_final_self_gap_m": self_gap(model, _theta(pe_x)).gap,
                    "speedup_with_self_contact": pe_wall / args.duration / out["contgrasp_with_self_contact_wall_per_sim_s"],
                    "centreline_max_diff_m": dmax, "centreline_max_diff_at_s_m": s_at})
    out.update(paper_overhead(max(args.repeats, 5)))
    out["load_average_end"] = os.getloadavg()[0]
    print(json.dumps(out, indent=2) if args.json else "\n".join(f"{k}: {v}" for k, v in out.items()))


if __name__ == "__main__":
    main()
