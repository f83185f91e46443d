"""Closed-loop paper scenario (Sec. V-C): contgrasp's implicit rod engine vs PyElastica.

Both engines simulate the same rod, environment, penalty contact and feedback law (eq. (19)) from
the straight arm at rest; PyElastica (explicit, at its largest stable step of ``--pe-dts``) takes
the couple through its rest curvature, with a ``LaplaceDissipationFilter``. Reports wall seconds
per simulated second of both (and of contgrasp's numpy path), their ratio and the distance
between the final centrelines; ``--also-unfiltered`` tries without the filter; part 2 compares
the engines open loop under a held couple. Needs the extra ``bench`` (pyelastica). Method and
results: docs/rod.md, "PyElastica comparison".

    python benchmarks/rod_vs_pyelastica.py --duration 3 --also-unfiltered --json
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from contgrasp_core.boundary import circle  # noqa: E402
from contgrasp_core.errors import InvalidParameterError  # noqa: E402
from contgrasp_core.control.law import feedback_couple  # noqa: E402
from contgrasp_core.rod import Obstacle, RodModel, RodSystem, _kernels  # noqa: E402
from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop  # noqa: E402
from contgrasp_core.control import paper_gains  # noqa: E402
from contgrasp_core.scenario import PAPER  # noqa: E402


def pyelastica_run(model: RodModel, obstacle: Obstacle | None, dt: float, duration: float, *, check_only: bool = False,
                   via: str = "rest_curvature", held_couple: np.ndarray | None = None, filter_order: int = 1,
                   shear_ratio: float = 100.0, stretch_ratio: float = 100.0, self_contact_k: float = 0.0):
    """Simulate the scenario in PyElastica; returns (node positions (N+1, 2), wall s, ok, max node speed).

    ``held_couple`` (N,) at the joints: open loop; None: the closed loop (eq. (19)).
    ``via``: how the couple enters, ``"rest_curvature"`` (``kappa_rest = -u/EI`` at the interior
    nodes, the joint couple at the clamp acts on the clamped element and is dropped, as in
    contgrasp's clamped base) or ``"torques"`` (equal and opposite external torques
    ``u_{i+1} - u_i`` on element i; the closed loop diverges this way at every step tried).
    ``filter_order``: PyElastica ``LaplaceDissipationFilter`` order (0 = none).
    ``shear_ratio`` = G / E and ``stretch_ratio`` scale the shear/stretch stiffness: the paper's
    rod is a Kirchhoff rod (inextensible, unshearable), so PyElastica is made nearly unshearable
    and inextensible (default G = 100 E, stretch x100), which also sets its stable step.
    ``obstacle`` None: no object (open loop only). ``self_contact_k`` > 0: PyElastica's own
    ``RodSelfContact`` with that stiffness (N/m per pair of elements) and damping
    ``model.contact_damping * model.h``.
    ``ok``: finite, max node speed < 10 m/s and max element rate < 1e3 rad/s at the end (the
    probe, ``check_only``, also stops at the first non-finite or > 1e4 rad/s state).
    """
    import elastica as ea

    if via not in ("rest_curvature", "torques"):
        raise ValueError(f"via must be 'rest_curvature' or 'torques', got {via!r}")
    n = model.n_elements
    if obstacle is None and held_couple is None:
        raise ValueError("the closed loop needs the obstacle")
    gains = None if obstacle is None else paper_gains(model, obstacle.boundary.params["R"])

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping, ea.Contact):
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
    if filter_order > 0:
        sim.dampen(rod).using(ea.LaplaceDissipationFilter, filter_order=int(filter_order))
    if self_contact_k > 0:
        sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=self_contact_k,
                                                   nu=model.contact_damping * model.h)
    ei_joint = model.joint_ei
    h = model.h
    r_el = model.r_centres
    torque_couple = held_couple if via == "torques" else None

    class Env(ea.NoForces):
        """Drag, contact (and, ``via="torques"``, the couple), identical to contgrasp's loads."""

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
            pr = None if obstacle is None else obstacle.project(c)
            pen = np.zeros(n) if pr is None else r_el - pr.signed_distance
            act = pen > 0
            if pr is not None and np.any(act):
                rate = -np.sum(vc * pr.normal_out, axis=1)
                fn = h * np.maximum(model.contact_stiffness * pen + model.contact_damping * rate, 0.0)
                f += np.where(act, fn, 0.0)[:, None] * pr.normal_out
            system.external_forces[:2, :-1] += 0.5 * f.T
            system.external_forces[:2, 1:] += 0.5 * f.T

        def apply_torques(self, system, time=0.0):
            if via != "torques":
                return
            if torque_couple is not None:
                u = torque_couple
            else:
                assert obstacle is not None and gains is not None
                x = system.position_collection[:2].T
                d3 = system.director_collection[2, :2, :].T  # material tangent director of each element
                th = np.unwrap(np.arctan2(d3[:, 1], d3[:, 0]))
                th_n = np.concatenate(([model.base_angle], 0.5 * (th[:-1] + th[1:])))
                pr = obstacle.project(x[:-1])
                alpha = pr.phi + 0.5 * np.pi - th_n
                u = feedback_couple(pr.signed_distance, alpha, ei_joint, gains.mu1, gains.mu2,
                                    length_unit=gains.length_unit)
            # couple on element i: u_{i+1} - u_i about +z = local director d2 (index 1)
            system.external_torques[1, :] += np.append(u[1:], 0.0) - u

    sim.add_forcing_to(rod).using(Env)
    sim.finalize()
    # rest curvature about d2 (= +z, index 1) at the N-1 interior nodes = contgrasp joints 1..N-1
    ei_in = ei_joint[1:]
    mu2_in = None if gains is None else (gains.mu2[1:] if np.ndim(gains.mu2) else gains.mu2)
    closed_rk = via == "rest_curvature" and held_couple is None
    if via == "rest_curvature" and held_couple is not None:
        rod.rest_kappa[1, :] = -held_couple[1:] / ei_in

    def control() -> None:
        """Sense (rho, alpha) at the interior nodes from the centreline; kappa_rest = -u / EI."""
        assert obstacle is not None and gains is not None
        x = rod.position_collection[:2].T
        e = np.diff(x, axis=0)
        tn = e[:-1] + e[1:]  # node tangent: the mean of the adjacent edges (the angles' mean, up to O(h^2))
        pr = obstacle.project(x[1:-1])
        alpha = pr.phi + 0.5 * np.pi - np.arctan2(tn[:, 1], tn[:, 0])
        u = feedback_couple(pr.signed_distance, alpha, ei_in, gains.mu1, mu2_in, length_unit=gains.length_unit)
        rod.rest_kappa[1, :] = -u / ei_in

    stepper = ea.PositionVerlet()
    steps = int(round(duration / dt))
    tm = 0.0
    t0 = time.perf_counter()
    for k in range(steps):
        try:
            if closed_rk:
                control()
            tm = stepper.step(sim, tm, dt)
        except InvalidParameterError:  # the state went non-finite: the law refuses it (diverged)
            return None, time.perf_counter() - t0, False, float("nan")
        if check_only and k % 100 == 0 and not (np.all(np.isfinite(rod.position_collection))
                                                and float(np.abs(rod.omega_collection).max()) < 1e4):
            return None, time.perf_counter() - t0, False, float("nan")
    wall = time.perf_counter() - t0
    x = rod.position_collection[:2].T.copy()
    speed = float(np.linalg.norm(rod.velocity_collection, axis=0).max())
    ok = (bool(np.all(np.isfinite(x))) and speed < 10.0 and float(np.abs(rod.omega_collection).max()) < 1e3)
    return x, wall, ok, speed


def contgrasp_held(model: RodModel, obstacle: Obstacle, couple: np.ndarray, duration: float, dt: float):
    """The project engine under a held couple profile (open loop); returns (nodes, wall s)."""
    from contgrasp_core.rod import RodLoads, chain

    system = RodSystem(model, obstacle)
    st = system.straight_state()
    dt_next = dt
    t0 = time.perf_counter()
    for _ in range(int(round(duration / dt))):
        st, info = system.advance(st, dt, RodLoads(couple=couple), dt_try=dt_next)
        dt_next = info["dt_next"]
    wall = time.perf_counter() - t0
    return chain.nodes(model, st.theta), wall


def _diff(model: RodModel, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Max distance (m) between two centrelines at equal arclength (node by node) and its s (m)."""
    d = np.hypot(*(a - b).T)
    return float(d.max()), float(model.s_nodes[int(d.argmax())])


def _probe(model, obstacle, dts, seconds, label, **kw) -> float | None:
    """Largest stable PyElastica step of ``dts`` (tried largest first) over ``seconds``, or None."""
    for dt in dts:
        _, _, ok, _ = pyelastica_run(model, obstacle, dt, seconds, check_only=True, **kw)
        print(f"{label}, pyelastica dt={dt:g}: {'stable' if ok else 'UNSTABLE'} over {seconds} s", flush=True)
        if ok:
            return dt
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=3.0, help="simulated seconds (default 3)")
    ap.add_argument("--dt", type=float, default=0.05, help="largest contgrasp step (s)")
    ap.add_argument("--probe", type=float, default=0.3, help="seconds simulated per stability probe")
    ap.add_argument("--pe-dts", type=str, default="5e-5,4e-5,3e-5,2e-5",
                    help="PyElastica steps to try, largest first")
    ap.add_argument("--filter-order", type=int, default=1,
                    help="PyElastica LaplaceDissipationFilter order in the closed loop (0 = none; default 1)")
    ap.add_argument("--shear-ratio", type=float, default=100.0,
                    help="PyElastica G/E, also the stretch-stiffness factor (default 100)")
    ap.add_argument("--also-unfiltered", action="store_true",
                    help="also probe the closed loop without the filter and with external torques")
    ap.add_argument("--held-kappa", type=float, default=30.0,
                    help="open-loop couple u = -EI(s) * kappa (1/m); 0 = the settled closed-loop couple")
    ap.add_argument("--open-duration", type=float, default=8.0,
                    help="simulated seconds of the open-loop check (default 8; the held curl settles slowly)")
    ap.add_argument("--skip-open-loop", action="store_true")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repeats", type=int, default=3, help="full closed-loop runs per engine (medians; default 3)")
    args = ap.parse_args()
    print(f"load average at start {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores",
          flush=True)

    model = PAPER.rod
    obstacle = Obstacle(circle(0.025, (0.08, 0.08)))
    dts = [float(s) for s in args.pe_dts.split(",")]
    stiff = {"shear_ratio": args.shear_ratio, "stretch_ratio": args.shear_ratio}
    out: dict = {"duration_s": args.duration, "pyelastica_shear_stretch_ratio": args.shear_ratio,
                 "pyelastica_filter_order": args.filter_order}
    # --- 1. closed loop (continuous implicit feedback) in contgrasp
    res = run_closed_loop(RodSystem(model, obstacle), paper_gains(model, 0.025),
                          ClosedLoopConfig(duration=args.duration, dt=args.dt, settle_speed=1e-12))
    slow = np.nonzero(res.max_speed >= 2e-4)[0]
    quiet_from = 0.0 if len(slow) == 0 else (float(res.t[slow[-1] + 1]) if slow[-1] + 1 < len(res.t) else None)
    cfg = ClosedLoopConfig(duration=args.duration, dt=args.dt, settle_speed=1e-12)
    cg_walls, cg_walls_numpy = [res.wall_time / res.t[-1]], []
    for r in range(args.repeats):
        if r > 0:
            cg_walls.append(run_closed_loop(RodSystem(model, obstacle), paper_gains(model, 0.025), cfg).wall_time / res.t[-1])
        _kernels.ENABLED = False
        try:
            cg_walls_numpy.append(run_closed_loop(RodSystem(model, obstacle), paper_gains(model, 0.025), cfg).wall_time
                                  / res.t[-1])
        finally:
            _kernels.ENABLED = True
    cg_wall = float(np.median(cg_walls))
    out.update({"closed_loop_contgrasp_wall_per_sim_s_runs": cg_walls,
                "closed_loop_contgrasp_numpy_path_wall_per_sim_s": float(np.median(cg_walls_numpy)),
                "closed_loop_contgrasp_numpy_path_wall_per_sim_s_runs": cg_walls_numpy,
                "closed_loop_contgrasp_kernels_speedup": float(np.median(cg_walls_numpy)) / cg_wall})
    out.update({"closed_loop_contgrasp_wall_per_sim_s": cg_wall,
                "closed_loop_contgrasp_final_max_speed": float(res.max_speed[-1]),
                "closed_loop_contgrasp_speed_below_2e-4_from_s": quiet_from})
    # --- 2. closed loop in PyElastica (rest curvature + filter): largest stable step, full run
    if args.also_unfiltered:  # the variants: probe, and a full run where stable
        for via, fo in (("rest_curvature", 0), ("torques", 0), ("torques", args.filter_order)):
            key = f"closed_loop_pyelastica_{via}_filter{fo}"
            dt = out[f"{key}_stable_dt"] = _probe(model, obstacle, dts, args.probe, f"closed loop via {via}, filter {fo}",
                                                  via=via, filter_order=fo, **stiff)
            if dt is not None:
                pe_x, pe_wall, ok, _ = pyelastica_run(model, obstacle, dt, args.duration, via=via, filter_order=fo,
                                                      **stiff)
                out.update({f"{key}_stable_full_run": ok, f"{key}_wall_per_sim_s": pe_wall / args.duration,
                            f"{key}_centreline_max_diff_m": _diff(model, pe_x, res.x[-1])[0]})
    dt = _probe(model, obstacle, dts, args.probe, f"closed loop via rest curvature, filter {args.filter_order}",
                filter_order=args.filter_order, **stiff)
    out["closed_loop_pyelastica_stable_dt"] = dt
    if dt is not None:
        pe_walls = []
        for _ in range(max(args.repeats, 1)):
            pe_x, pe_wall, ok, speed = pyelastica_run(model, obstacle, dt, args.duration,
                                                      filter_order=args.filter_order, **stiff)
            pe_walls.append(pe_wall / args.duration)
            print(f"pyelastica full run: {pe_walls[-1]:.2f} wall s per simulated s", flush=True)
        pe_med = float(np.median(pe_walls))
        dmax, s_at = _diff(model, pe_x, res.x[-1])
        out.update({"closed_loop_pyelastica_stable_full_run": ok,
                    "closed_loop_pyelastica_final_max_speed": speed,
                    "closed_loop_pyelastica_wall_per_sim_s": pe_med,
                    "closed_loop_pyelastica_wall_per_sim_s_runs": pe_walls,
                    "closed_loop_speedup": pe_med / cg_wall,
                    "closed_loop_speedup_numpy_path": pe_med / float(np.median(cg_walls_numpy)),
                    "closed_loop_centreline_max_diff_m": dmax, "closed_loop_centreline_max_diff_at_s_m": s_at,
                    "closed_loop_tip_contgrasp_m": res.x[-1][-1].tolist(), "closed_loop_tip_pyelastica_m": pe_x[-1].tolist()})
    # --- 3. open loop: both engines under a held couple profile (no filter)
    if not args.skip_open_loop:
        u = res.couple[-1] if args.held_kappa <= 0 else -model.joint_ei * args.held_kappa
        out["open_loop_held_kappa_per_m"] = args.held_kappa if args.held_kappa > 0 else "closed-loop couple"
        t_open = args.open_duration
        out["open_loop_duration_s"] = t_open
        cg_x, cg_wall_open = contgrasp_held(model, obstacle, u, t_open, args.dt)
        out["open_loop_contgrasp_wall_per_sim_s"] = cg_wall_open / t_open
        for via in ("torques", "rest_curvature"):
            dt = _probe(model, obstacle, dts, args.probe, f"open loop via {via}", via=via, held_couple=u,
                        filter_order=0, **stiff)
            out[f"open_loop_{via}_pyelastica_dt"] = dt
            if dt is None:
                continue
            pe_x, pe_wall, ok, speed = pyelastica_run(model, obstacle, dt, t_open, via=via, held_couple=u,
                                                      filter_order=0, **stiff)
            dmax, s_at = _diff(model, pe_x, cg_x)
            out.update({f"open_loop_{via}_pyelastica_stable_full_run": ok,
                        f"open_loop_{via}_pyelastica_wall_per_sim_s": pe_wall / t_open,
                        f"open_loop_{via}_speedup": pe_wall / cg_wall_open,
                        f"open_loop_{via}_centreline_max_diff_m": dmax,
                        f"open_loop_{via}_centreline_max_diff_at_s_m": s_at})
    out["load_average_end"] = os.getloadavg()[0]
    print(json.dumps(out, indent=2) if args.json else "\n".join(f"{k}: {v}" for k, v in out.items()))
    print(f"load average at end {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
