"""Closed-loop paper scenario (Sec. V-C): contgrasp's implicit rod engine vs PyElastica.

Both simulate the same rod (L = 0.2 m, radius 1 cm -> 1 mm, density 1042, E = 10 kPa, Poisson
0.5, 100 elements), the same environment (mass-proportional damping zeta, quadratic drag
5110 / 25.55 per unit projected area, the same penalty contact law on the element centres
against the circle of radius 2.5 cm at (8, 8) cm) and the same feedback law (eq. dynamic_feedback
with mu1 = 1 and the adaptive mu2, centimetre units). PyElastica (explicit PositionVerlet, the
feedback re-evaluated every step) runs at the largest stable step found by a sweep; the project
engine runs continuous implicit feedback with adaptive steps up to ``--dt``.

Reports wall seconds per simulated second for both, their ratio and the max distance between
the two final centrelines at equal arclength. Needs the optional extra ``bench`` (pyelastica).

Part 2 probes PyElastica on the closed loop; part 3 compares both engines open loop, under a
held couple ``u = -EI(s) kappa`` (default kappa = 30 /m: the arm curls onto the object), same rod,
drag, damping and contact law.

    python benchmarks/rod_vs_pyelastica.py --duration 3
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from contgrasp_core.boundary import circle  # noqa: E402
from contgrasp_core.feedback import feedback_couple  # noqa: E402
from contgrasp_core.rod import Obstacle, RodModel, RodSystem  # noqa: E402
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, paper_gains, run_closed_loop  # noqa: E402
from contgrasp_core.rod.scenario import paper_model  # noqa: E402


def pyelastica_run(model: RodModel, obstacle: Obstacle, dt: float, duration: float, *, check_only: bool = False,
                   shear_ratio: float = 100.0, held_couple: np.ndarray | None = None, stretch_ratio: float = 100.0):
    """Simulate the scenario in PyElastica; returns (node positions (N+1, 2), wall s, ok).

    ``shear_ratio`` = G / E. The paper's rod is a Kirchhoff rod (inextensible, unshearable); with
    the physical G = E/3 the centimetre feedback couples shear the soft rod's directors past
    90 degrees and they spin up without bound (observed at every dt), so PyElastica is made
    nearly unshearable with G = 100 E (default), which also lowers its stable step.
    """
    import elastica as ea

    n = model.n_elements
    gains = paper_gains(model, obstacle.boundary.params["R"])

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        pass

    sim = Sim()
    rod = ea.CosseratRod.straight_rod(
        n, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), model.length,
        model.r_centres.copy(), model.density, youngs_modulus=model.youngs_modulus,
        shear_modulus=model.youngs_modulus * shear_ratio)
    rod.shear_matrix[2, 2, :] *= stretch_ratio
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    if model.damping > 0:
        sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=model.damping, time_step=dt)
    ei_joint = model.joint_ei
    h = model.h
    r_el = model.r_centres

    class Env(ea.NoForces):
        """Drag, contact and the feedback couple, identical to contgrasp's loads."""

        def apply_forces(self, system, time=0.0):
            x = system.position_collection[:2].T
            v = system.velocity_collection[:2].T
            c = 0.5 * (x[:-1] + x[1:])
            vc = 0.5 * (v[:-1] + v[1:])
            t = system.tangents[:2].T
            nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
            vn = np.sum(vc * nrm, axis=1)
            vt = np.sum(vc * t, axis=1)
            dl = 2.0 * r_el * h
            f = -(model.drag_normal * dl * np.abs(vn) * vn)[:, None] * nrm
            f -= (model.drag_tangential * dl * np.abs(vt) * vt)[:, None] * t
            pr = obstacle.project(c)
            pen = r_el - pr.signed_distance
            act = pen > 0
            if np.any(act):
                rate = -np.sum(vc * pr.normal_out, axis=1)
                fn = h * np.maximum(model.contact_stiffness * pen + model.contact_damping * rate, 0.0)
                f += np.where(act, fn, 0.0)[:, None] * pr.normal_out
            system.external_forces[:2, :-1] += 0.5 * f.T
            system.external_forces[:2, 1:] += 0.5 * f.T

        def apply_torques(self, system, time=0.0):
            if held_couple is not None:
                system.external_torques[1, :] += np.append(held_couple[1:], 0.0) - held_couple
                return
            x = system.position_collection[:2].T
            d3 = system.director_collection[2, :2, :].T  # material tangent director of each element
            th = np.unwrap(np.arctan2(d3[:, 1], d3[:, 0]))
            th_n = np.concatenate(([model.base_angle], 0.5 * (th[:-1] + th[1:])))
            pr = obstacle.project(x[:-1])
            alpha = pr.phi + 0.5 * np.pi - th_n
            u = feedback_couple(pr.signed_distance, alpha, ei_joint, gains.mu1, gains.mu2,
                                length_unit=gains.length_unit)
            u_next = np.append(u[1:], 0.0)
            # couple on element i: u_{i+1} - u_i about +z = local director d2 (index 1)
            system.external_torques[1, :] += u_next - u

    sim.add_forcing_to(rod).using(Env)
    sim.finalize()
    stepper = ea.PositionVerlet()
    steps = int(round(duration / dt))
    tm = 0.0
    t0 = time.perf_counter()
    for _ in range(steps):
        tm = stepper.step(sim, tm, dt)
        if check_only and not np.all(np.isfinite(rod.position_collection)):
            return None, time.perf_counter() - t0, False
    wall = time.perf_counter() - t0
    x = rod.position_collection[:2].T.copy()
    ok = bool(np.all(np.isfinite(x))) and float(np.abs(rod.velocity_collection).max()) < 10.0
    return x, wall, ok


def contgrasp_held(model: RodModel, obstacle: Obstacle, couple: np.ndarray, duration: float, dt: float):
    """The project engine under a held couple profile (open loop); returns (nodes, wall s)."""
    from contgrasp_core.rod import RodLoads, chain
    from contgrasp_core.rod.closed_loop import _single_thread_blas

    system = RodSystem(model, obstacle)
    st = system.straight_state()
    dt_next = dt
    with _single_thread_blas():
        t0 = time.perf_counter()
        for _ in range(int(round(duration / dt))):
            st, info = system.advance(st, dt, RodLoads(couple=couple), dt_try=dt_next)
            dt_next = info["dt_next"]
        wall = time.perf_counter() - t0
    return chain.nodes(model, st.theta), wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=4.0, help="simulated seconds (default 4)")
    ap.add_argument("--dt", type=float, default=0.05, help="largest contgrasp step (s)")
    ap.add_argument("--probe", type=float, default=0.2, help="seconds simulated per stability probe")
    ap.add_argument("--pe-dts", type=str, default="2e-4,1e-4,5e-5,2e-5,1e-5",
                    help="PyElastica steps to try, largest first")
    ap.add_argument("--shear-ratio", type=float, default=100.0, help="PyElastica G/E (default 100)")
    ap.add_argument("--held-kappa", type=float, default=30.0,
                    help="open-loop couple u = -EI(s) * kappa (1/m); 0 = the settled closed-loop couple")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    model = paper_model()
    obstacle = Obstacle(circle(0.025, (0.08, 0.08)))
    out: dict = {"duration_s": args.duration}
    # --- 1. closed loop (continuous feedback) in contgrasp
    res = run_closed_loop(RodSystem(model, obstacle), paper_gains(model, 0.025),
                          ClosedLoopConfig(duration=args.duration, dt=args.dt, settle_speed=1e-12))
    out.update({"closed_loop_contgrasp_wall_per_sim_s": res.wall_time / res.t[-1],
                "closed_loop_contgrasp_final_max_speed": float(res.max_speed[-1])})
    # --- 2. closed loop in PyElastica: probe for a stable step
    out["closed_loop_pyelastica_stable_dt"] = None
    for dt in [float(s) for s in args.pe_dts.split(",")]:
        _, _, ok = pyelastica_run(model, obstacle, dt, args.probe, check_only=True, shear_ratio=args.shear_ratio)
        print(f"closed loop, pyelastica dt={dt:g}: {'stable' if ok else 'UNSTABLE'} over {args.probe} s", flush=True)
        if ok:
            out["closed_loop_pyelastica_stable_dt"] = dt
            break
    # --- 3. open loop: both engines under a held couple profile
    u = res.couple[-1] if args.held_kappa <= 0 else -model.joint_ei * args.held_kappa
    out["open_loop_held_kappa_per_m"] = args.held_kappa if args.held_kappa > 0 else "closed-loop couple"
    cg_x, cg_wall = contgrasp_held(model, obstacle, u, args.duration, args.dt)
    out.update({"open_loop_contgrasp_wall_per_sim_s": cg_wall / args.duration})
    for dt in [float(s) for s in args.pe_dts.split(",")]:
        _, _, ok = pyelastica_run(model, obstacle, dt, args.probe, check_only=True, shear_ratio=args.shear_ratio,
                                  held_couple=u)
        print(f"open loop, pyelastica dt={dt:g}: {'stable' if ok else 'UNSTABLE'} over {args.probe} s", flush=True)
        if ok:
            pe_x, pe_wall, ok = pyelastica_run(model, obstacle, dt, args.duration, shear_ratio=args.shear_ratio,
                                               held_couple=u)
            out.update({"open_loop_pyelastica_dt": dt, "open_loop_pyelastica_stable_full_run": ok,
                        "open_loop_pyelastica_wall_per_sim_s": pe_wall / args.duration,
                        "open_loop_speedup": (pe_wall / args.duration) / (cg_wall / args.duration),
                        "open_loop_centreline_max_diff_m": float(np.hypot(*(pe_x - cg_x).T).max()),
                        "open_loop_contgrasp_vs_closed_loop_max_diff_m": float(np.hypot(*(cg_x - res.x[-1]).T).max())})
            break
    print(json.dumps(out, indent=2) if args.json else "\n".join(f"{k}: {v}" for k, v in out.items()))


if __name__ == "__main__":
    main()
